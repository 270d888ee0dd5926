defmodule Dolphin.MAVLink.PropertiesTest do
  # Property tests of the codec: PropEr generators of random messages, frames
  # and byte streams, checked through Dolphin.Property (test/support).
  use ExUnit.Case, async: true

  # Thousands of cases each, all CPU: 20 s for the module on a quiet machine,
  # over a minute a test with both cores busy elsewhere.
  @moduletag timeout: 600_000

  import Bitwise
  import Dolphin.Property

  alias :proper_types, as: T
  alias Dolphin.MAVLink.{Frame, Parser, Signing}
  alias Dolphin.MAVLink.Ardupilotmega, as: APM

  @dialect APM
  @magic [0xFD, 0xFE]
  # The longest frame: signed MAVLink 2 with a 255-byte payload (10 header + 255 + 2 CRC + 13 signature).
  @max_frame 280
  # The key of the parsers with signing in the random-bytes property; frames signed with it pass.
  @key :binary.copy(<<0x5A>>, 32)

  ## Properties

  test "every message of the dialect survives encode/decode: MAVLink 2, signed MAVLink 2 and MAVLink 1" do
    modules = APM.messages()
    assert length(modules) == 301

    for module <- modules do
      check(forall({message(module), header(), signer()}, &round_trip/1), numtests: 60)
    end
  end

  test "the parser never raises on random bytes, in any chunks, and accounts for every byte" do
    check(
      forall({noisy_stream(), chunk_sizes(), parser_signing(), T.elements([:drop, :forward])}, fn {bytes, sizes, signing, unknown} ->
        {frames, parser} = feed_chunks(Parser.new(signing: signing, unknown: unknown), bytes, sizes)
        stats = Parser.stats(parser)

        assert stats.bytes == byte_size(bytes)
        # Every byte is either in a returned frame or counted as skipped.
        assert stats.bytes_skipped + Enum.sum(Enum.map(frames, &byte_size(&1.raw))) == byte_size(bytes)
        raw = Enum.count(frames, &(&1.message == nil))
        assert stats.frames + raw == length(frames)
        # Unknown-id frames come out only when forwarded.
        if unknown == :drop, do: assert(raw == 0), else: assert(raw <= stats.unknown_id)
        # Frames are made of input bytes.
        assert Enum.all?(frames, &(:binary.match(bytes, &1.raw) != :nomatch))
      end),
      numtests: 1000
    )
  end

  # As Parser's moduledoc promises (an unknown-id frame at the end of a chunk
  # waits for the byte after it; feed_chunks ends the stream with finish/1).
  test "what the parser returns does not depend on how the stream is cut into chunks" do
    check(
      forall({noisy_stream(), chunk_sizes(), parser_signing()}, fn {bytes, sizes, signing} ->
        {whole, parser} = feed_whole(Parser.new(signing: signing), bytes)
        whole_stats = Parser.stats(parser)
        {chunked, parser} = feed_chunks(Parser.new(signing: signing), bytes, sizes)

        assert Enum.map(chunked, &{&1.raw, norm(&1.message)}) == Enum.map(whole, &{&1.raw, norm(&1.message)})
        assert Parser.stats(parser) == whole_stats
      end),
      numtests: 500
    )
  end

  # Dolphin.MAVLink.Native: the C fast path builds the very terms the
  # Elixir decoder builds, and stops where it must (the stats agree too).
  test "the parser's C fast path decodes every stream exactly as the Elixir decoder does, in any chunks" do
    assert Dolphin.MAVLink.Native.available?(), "c_src/dolphin_native.c was not built (no C compiler?)"

    check(
      forall({noisy_stream(), chunk_sizes(), T.elements([:drop, :forward])}, fn {bytes, sizes, unknown} ->
        {fast, fast_parser} = feed_chunks(Parser.new(unknown: unknown), bytes, sizes)
        {slow, slow_parser} = feed_chunks(Parser.new(unknown: unknown, batch: false), bytes, sizes)

        assert Enum.map(fast, &exact/1) == Enum.map(slow, &exact/1)
        assert Parser.stats(fast_parser) == Parser.stats(slow_parser)
      end),
      numtests: 1000
    )
  end

  test "valid frames behind garbage without magic bytes are all recovered, in order, in any chunks" do
    check(
      forall({T.resize(12, T.list({garbage(:no_magic), frame()})), garbage(:no_magic), chunk_sizes()}, fn {pairs, tail, sizes} ->
        stream = IO.iodata_to_binary([Enum.map(pairs, fn {garbage, {bytes, _}} -> [garbage, bytes] end), tail])
        {frames, parser} = feed_chunks(Parser.new(), stream, sizes)
        stats = Parser.stats(parser)

        # No magic byte outside the frames: no candidate but the real frames, hence no unknown-id frame either.
        assert Enum.map(frames, &{&1.raw, norm(&1.message)}) == Enum.map(pairs, fn {_, {bytes, msg}} -> {bytes, norm(msg)} end)
        assert stats.frames == length(pairs)
        assert stats.bytes_skipped == byte_size(stream) - Enum.sum(Enum.map(pairs, fn {_, {bytes, _}} -> byte_size(bytes) end))
      end),
      numtests: 400
    )
  end

  # What the parser's design guarantees when garbage may hold magic bytes: a
  # false candidate at a magic byte claims at most @max_frame bytes, so when at
  # least that many bytes without a magic byte follow the garbage, every false
  # candidate (failed, or accepted as an unknown-id frame) ends before the next
  # real frame, and the scan, which only ever skips to the next magic byte or
  # one byte past a failed candidate, reaches that frame's first byte. Garbage
  # holding, by chance, a CRC-valid frame of a known id (a 2^-16 coincidence per
  # candidate) is not garbage: the generator leaves it out.
  #
  # Without the filler, a false candidate can still be waiting for its bytes
  # when the stream ends; Parser.finish/1 then drops it and scans on inside it
  # (see the test "a false magic byte right before a frame ...").
  test "valid frames behind garbage with magic bytes and #{@max_frame} bytes of filler are all recovered, in any chunks" do
    check(
      forall({T.resize(8, T.list({gap(), frame()})), gap(), chunk_sizes()}, fn {pairs, tail, sizes} ->
        stream = IO.iodata_to_binary([Enum.map(pairs, fn {gap, {bytes, _}} -> [gap, bytes] end), tail])
        {frames, _parser} = feed_chunks(Parser.new(), stream, sizes)

        known = for %Frame{message: msg} = f <- frames, msg != nil, do: {f.raw, norm(msg)}
        assert known == Enum.map(pairs, fn {_, {bytes, msg}} -> {bytes, norm(msg)} end)
      end),
      numtests: 400
    )
  end

  # The stronger resynchronisation guarantee: no filler between garbage and the
  # next frame, so false candidates overlap the real frames after them. The
  # parser drops the first garbage byte, so it is out of sync at every false
  # candidate, and an unknown-id candidate is then refused; a known-id one
  # fails its CRC and the scan resumes one byte after its magic, which reaches
  # the next real frame before any byte of it is skipped. (Garbage starting with
  # a magic byte right after a frame is different, see the next test.)
  test "valid frames right behind garbage with magic bytes are all recovered, in any chunks" do
    junk = map({non_magic(), garbage(:magic)}, fn {b, g} -> <<b, g::binary>> end)

    check(
      forall({stream_of(junk, false), chunk_sizes()}, fn {{stream, expected, _}, sizes} ->
        {frames, _parser} = feed_chunks(Parser.new(), stream, sizes)

        known = for %Frame{message: msg} = f <- frames, msg != nil, do: {f.raw, norm(msg)}
        assert known == Enum.map(expected, fn {bytes, msg} -> {bytes, norm(msg)} end)
      end),
      numtests: 400
    )
  end

  # Truncated and corrupted frames, each right before a valid one. A signed
  # frame cut in its signature has an intact CRC and borrows the next frame's
  # first bytes as signature: only a parser that checks signatures can refuse
  # it (and then resumes one byte after its magic), so the parser here has the
  # key. A corrupted msgid can make an unknown-id frame, accepted (in sync and
  # followed by a magic byte) with `message: nil` and exactly its own bytes.
  test "valid frames right after truncated or corrupted frames are all recovered, in any chunks" do
    junk = T.frequency([{2, truncated_frame()}, {2, corrupted_frame()}, {1, unknown_frame()}, {1, T.exactly(<<>>)}])

    check(
      forall({stream_of(junk, true), chunk_sizes()}, fn {{stream, expected, _}, sizes} ->
        {frames, _parser} = feed_chunks(Parser.new(signing: Signing.new(key: @key, unsigned: :accept, timestamp: 0)), stream, sizes)

        known = for %Frame{message: msg} = f <- frames, msg != nil, do: {f.raw, norm(msg)}
        assert known == Enum.map(expected, fn {bytes, msg} -> {bytes, norm(msg)} end)
      end),
      numtests: 400
    )
  end

  # Each unknown-id frame here is in sync (right after a frame, or first) and
  # followed by a magic byte (a last known frame closes the stream: what becomes
  # of an unknown-id frame that ends the data is not this property's concern).
  test "frames of unknown ids between frames come out raw, in order, in any chunks" do
    item = T.frequency([{3, frame()}, {1, map(unknown_frame(), &{&1, nil})}])

    items = map({T.resize(10, T.list(item)), frame()}, fn {items, last} -> items ++ [last] end)

    check(
      forall({items, chunk_sizes()}, fn {items, sizes} ->
        stream = IO.iodata_to_binary(Enum.map(items, &elem(&1, 0)))
        {frames, parser} = feed_chunks(Parser.new(unknown: :forward), stream, sizes)
        stats = Parser.stats(parser)

        assert Enum.map(frames, &{&1.raw, norm(&1.message)}) == Enum.map(items, fn {bytes, msg} -> {bytes, norm(msg)} end)
        assert stats.unknown_id == Enum.count(items, &(elem(&1, 1) == nil))
        assert stats.bytes_skipped == 0
      end),
      numtests: 300
    )
  end

  describe "a frame of an unknown id" do
    setup do
      h1 = Frame.encode(%APM.Heartbeat{type: 1}, sysid: 1)
      h2 = Frame.encode(%APM.Heartbeat{type: 2}, sysid: 2)
      # Well formed, id 0xFFFFFF, with h2 inside its payload.
      payload = <<0>> <> h2 <> :binary.copy(<<0>>, 10)
      unknown = <<0xFD, byte_size(payload), 0, 0, 0, 9, 9, 0xFFFFFF::little-24, payload::binary, 0xAB, 0xCD>>
      assert APM.message_info(0xFFFFFF) == nil
      %{h1: h1, h2: h2, unknown: unknown}
    end

    test "is refused by default (its checksum cannot be checked); the frame inside it is found", %{h1: h1, h2: h2, unknown: unknown} do
      {frames, parser} = Parser.feed(Parser.new(), h1 <> unknown <> h1)
      assert Enum.map(frames, & &1.raw) == [h1, h2, h1]
      assert Parser.stats(parser).unknown_id == 1
    end

    test "is returned raw right after a frame when a magic byte follows it, when forwarding", %{h1: h1, unknown: unknown} do
      {frames, _} = Parser.feed(Parser.new(unknown: :forward), h1 <> unknown <> h1)
      assert Enum.map(frames, & &1.raw) == [h1, unknown, h1]
      assert [%APM.Heartbeat{}, nil, %APM.Heartbeat{}] = Enum.map(frames, & &1.message)
      assert Enum.at(frames, 1).msgid == 0xFFFFFF
    end

    test "is not trusted when other bytes follow it: the frame inside it is found", %{h1: h1, h2: h2, unknown: unknown} do
      {frames, _} = Parser.feed(Parser.new(unknown: :forward), h1 <> unknown <> <<0>> <> h1)
      assert Enum.map(frames, & &1.raw) == [h1, h2, h1]
    end

    test "is not trusted after dropped bytes: the frame inside it is found", %{h1: h1, h2: h2, unknown: unknown} do
      {frames, _} = Parser.feed(Parser.new(unknown: :forward), "xx" <> unknown <> h1)
      assert Enum.map(frames, & &1.raw) == [h2, h1]
    end
  end

  # CRC-16/MCRF4XX detects every single-bit error in the bytes it covers, and a
  # flipped bit of the magic byte leaves no candidate there (0xFD and 0xFE are
  # two bits apart). A flipped msgid bit changes the CRC_EXTRA too; it was
  # checked exhaustively (every message, msgid bit and MAVLink 2 payload length
  # of this dialect) that no such pair of changes cancels out in the CRC.
  #
  # The length byte is left out: a shorter length makes the CRC be read from two
  # payload bytes, which match the checksum of the shortened frame once in 2^16
  # (a real collision, shown by the next test). A longer length only makes the
  # parser wait for bytes that never come.
  #
  # After the corrupted candidate fails, the parser looks for frames inside it,
  # by design; a CRC-valid frame of a known id hidden in the payload (again a
  # 2^-16 coincidence) would be legitimately returned. So the property is:
  # nothing is returned from the corrupted frame's own first byte, not even a
  # raw frame (a flipped msgid bit can make an unknown id, which a parser that
  # does not forward unknown ids refuses), and any frame returned lies strictly
  # inside it.
  test "a frame with one flipped bit outside the length byte never decodes" do
    check(
      forall({flipped_frame(), chunk_sizes()}, fn {{flipped, _original}, sizes} ->
        {frames, _parser} = feed_chunks(Parser.new(), flipped, sizes)

        for %Frame{message: msg, raw: raw} <- frames do
          refute :binary.longest_common_prefix([raw, flipped]) == byte_size(raw),
                 "the corrupted frame decoded as #{inspect(msg)}"

          assert Enum.any?(:binary.matches(flipped, raw), fn {pos, _} -> pos > 0 end)
        end

        true
      end),
      numtests: 5000
    )
  end

  test "a flipped length bit can give a frame whose CRC still matches (why the property above spares the length byte)" do
    # Found by a search over custom_mode and mavlink_version.
    bytes = Frame.encode(%APM.Heartbeat{custom_mode: 16, mavlink_version: 175}, sysid: 1, compid: 1)
    assert <<0xFD, 9, rest::binary>> = bytes

    assert {:ok, %Frame{message: %APM.Heartbeat{custom_mode: 16, mavlink_version: 0}}, "u"} = Frame.decode(<<0xFD, bxor(9, 1), rest::binary>>, @dialect)
  end

  test "a false magic byte right before a frame only delays it until the false candidate's length has arrived" do
    # A byte 0xFE read as a MAVLink 1 header claims 8 + 0xFD bytes (the next
    # frame's magic is its length byte): the parser waits for them, then the
    # candidate fails its CRC and the scan resumes one byte after it.
    heartbeat = Frame.encode(%APM.Heartbeat{type: 2}, sysid: 1)
    {frames, parser} = Parser.feed(Parser.new(), <<0xFE>> <> heartbeat)
    assert frames == []

    {frames, parser} = Parser.feed(parser, :binary.copy(<<0>>, @max_frame))
    assert [%Frame{message: %APM.Heartbeat{type: 2}, raw: ^heartbeat}] = frames
    assert %{frames: 1, bad_crc: 1} = Parser.stats(parser)
  end

  test "when the stream ends inside a false candidate, the frames behind it are still returned" do
    heartbeat = Frame.encode(%APM.Heartbeat{type: 2}, sysid: 1)
    {[], parser} = Parser.feed(Parser.new(), <<0xFE>> <> heartbeat)
    {frames, parser} = Parser.finish(parser)
    assert [%Frame{message: %APM.Heartbeat{type: 2}, raw: ^heartbeat}] = frames
    assert %{frames: 1, truncated: 1, bytes_skipped: 1} = Parser.stats(parser)
    assert {[], ^parser} = Parser.finish(parser)
  end

  test "an unknown-id frame that ends the stream is returned by finish/1" do
    h1 = Frame.encode(%APM.Heartbeat{type: 1}, sysid: 1)
    unknown = <<0xFD, 1, 0, 0, 0, 9, 9, 0xFFFFFF::little-24, 7, 0xAB, 0xCD>>
    {[first], parser} = Parser.feed(Parser.new(unknown: :forward), h1 <> unknown)
    assert first.raw == h1
    {[frame], parser} = Parser.finish(parser)
    assert frame.raw == unknown and frame.message == nil
    assert %{frames: 1, unknown_id: 1, bytes_skipped: 0} = Parser.stats(parser)
  end

  ## Round trip

  defp round_trip({%module{} = msg, {sysid, compid, seq, compat}, {key, link_id, timestamp}}) do
    id = module.__mavlink__(:id)
    header = [sysid: sysid, compid: compid, seq: seq]

    # MAVLink 2
    bytes = Frame.encode(msg, header ++ [compat_flags: compat])
    assert {:ok, frame, ""} = Frame.decode(bytes, @dialect)
    assert_header(frame, 2, id, sysid, compid, seq, bytes)
    assert {frame.incompat_flags, frame.compat_flags, frame.signature} == {0, compat, nil}
    assert norm(frame.message) == norm(msg)

    # Signed MAVLink 2
    {signed, _} = Signing.encode(Signing.new(key: key, link_id: link_id, timestamp: 0), msg, header ++ [compat_flags: compat, now: timestamp])
    assert {:ok, frame, ""} = Frame.decode(signed, @dialect)
    assert_header(frame, 2, id, sysid, compid, seq, signed)
    assert {frame.incompat_flags, frame.compat_flags} == {1, compat}
    assert %{link_id: ^link_id, timestamp: ^timestamp} = frame.signature
    assert norm(frame.message) == norm(msg)
    assert {:ok, checker} = Signing.verify(Signing.new(key: key, timestamp: 0), frame)
    assert {:error, :old_timestamp, _} = Signing.verify(checker, frame)
    <<k, other_key::binary>> = key
    assert {:error, :bad_signature, _} = Signing.verify(Signing.new(key: <<bxor(k, 1), other_key::binary>>), frame)

    # MAVLink 1: ids below 256 only, without extension fields
    if id < 256 do
      bytes = Frame.encode(msg, [version: 1] ++ header)
      assert {:ok, frame, ""} = Frame.decode(bytes, @dialect)
      assert_header(frame, 1, id, sysid, compid, seq, bytes)
      assert norm(frame.message) == norm(without_extensions(msg))
    else
      assert_raise ArgumentError, fn -> Frame.encode(msg, [version: 1] ++ header) end
    end
  end

  defp assert_header(frame, version, id, sysid, compid, seq, bytes) do
    assert {frame.version, frame.msgid, frame.sysid, frame.compid, frame.seq, frame.raw} ==
             {version, id, sysid, compid, seq, bytes}
  end

  defp without_extensions(%module{} = msg) do
    zeros = for %{extension: true} = f <- module.__mavlink__(:fields), do: {f.name, zero(f)}
    struct!(msg, zeros)
  end

  defp zero(%{type: :char}), do: ""
  defp zero(%{type: t, array_length: nil}) when t in [:float, :double], do: 0.0
  defp zero(%{array_length: nil}), do: 0
  defp zero(%{array_length: n} = f), do: List.duplicate(zero(%{f | array_length: nil}), n)

  # Floats compared by their bits: in OTP 25, -0.0 == 0.0 (and even -0.0 === 0.0).
  # A frame with its message's floats by their bits (-0.0 and 0.0 differ).
  defp exact(%Frame{} = f), do: %{f | message: f.message && norm(f.message)}

  defp norm(%module{} = msg), do: {module, msg |> Map.from_struct() |> Enum.sort() |> Enum.map(fn {k, v} -> {k, norm(v)} end)}
  defp norm(list) when is_list(list), do: Enum.map(list, &norm/1)
  defp norm(float) when is_float(float), do: {:float, <<float::float-64>>}
  defp norm(other), do: other

  ## Generators: values

  # ?LET of PropEr: `fun` maps a generated value to a generator (bind) or to a value (map).
  defp bind(gen, fun), do: T.bind(gen, fun, false)
  defp map(gen, fun), do: bind(gen, &T.exactly(fun.(&1)))

  # Uniform over 0..2^bits-1: PropEr 1.2's integer/2 is only uniform for narrow ranges.
  defp uint(bits) when bits <= 16, do: T.integer(0, (1 <<< bits) - 1)

  defp uint(bits) do
    map(T.vector(div(bits + 15, 16), T.integer(0, 0xFFFF)), fn words ->
      Enum.reduce(words, 0, &(&2 <<< 16 ||| &1)) &&& (1 <<< bits) - 1
    end)
  end

  @ints %{
    uint8: {8, false},
    int8: {8, true},
    uint16: {16, false},
    int16: {16, true},
    uint32: {32, false},
    int32: {32, true},
    uint64: {64, false},
    int64: {64, true}
  }

  defp scalar(type) when is_map_key(@ints, type) do
    {bits, signed?} = @ints[type]
    {min, max} = if signed?, do: {-(1 <<< (bits - 1)), (1 <<< (bits - 1)) - 1}, else: {0, (1 <<< bits) - 1}
    any = if signed?, do: map(uint(bits), &signed(&1, bits)), else: uint(bits)
    T.frequency([{4, any}, {1, T.elements(Enum.uniq([min, max, 0, 1, min + 1, max - 1]))}])
  end

  defp scalar(:float), do: float_value(32)
  defp scalar(:double), do: float_value(64)

  defp signed(u, bits) do
    <<v::signed-size(bits)>> = <<u::size(bits)>>
    v
  end

  # Every value here is exact in its width, so it must come back unchanged.
  defp float_value(bits) do
    {exp_bits, frac_bits} = if bits == 32, do: {8, 23}, else: {11, 52}
    exp_max = (1 <<< exp_bits) - 1
    max_finite = (exp_max - 1) <<< frac_bits ||| (1 <<< frac_bits) - 1
    min_normal = 1 <<< frac_bits
    max_subnormal = (1 <<< frac_bits) - 1
    quiet_nan = exp_max <<< frac_bits ||| 1 <<< (frac_bits - 1)
    sign = 1 <<< (bits - 1)

    patterns =
      [0, sign, 1, sign ||| 1, max_subnormal, min_normal, max_finite, sign ||| max_finite] ++
        [
          exp_max <<< frac_bits,
          sign ||| exp_max <<< frac_bits,
          quiet_nan,
          quiet_nan ||| 1,
          sign ||| quiet_nan,
          exp_max <<< frac_bits ||| 1
        ]

    T.frequency([
      {4, map(uint(bits), &float_of_bits(&1, bits))},
      {2, map(T.elements(patterns), &float_of_bits(&1, bits))},
      {1, map(T.integer(-4096, 4096), &(&1 / 16))}
    ])
  end

  # The value a field holds for given IEEE 754 bits, per Dolphin.MAVLink.Value's moduledoc.
  defp float_of_bits(bits, 32), do: special(bits, 0x7F800000, 0x7FC00000, 31) || finite(<<bits::32>>)
  defp float_of_bits(bits, 64), do: special(bits, 0x7FF0000000000000, 0x7FF8000000000000, 63) || finite(<<bits::64>>)

  defp finite(<<f::float-32>>), do: f
  defp finite(<<f::float-64>>), do: f

  defp special(bits, inf, quiet_nan, sign_bit) do
    cond do
      (bits &&& inf) != inf -> nil
      bits == inf -> :infinity
      bits == (inf ||| 1 <<< sign_bit) -> :neg_infinity
      bits == quiet_nan -> :nan
      true -> {:nan, bits}
    end
  end

  defp field_value(%{type: :char, array_length: n}) do
    n = n || 1

    length = T.frequency([{3, T.integer(0, n)}, {1, T.exactly(n)}])
    bind(length, fn len -> map(T.vector(len, T.integer(0x20, 0x7E)), &List.to_string/1) end)
  end

  defp field_value(%{type: type, array_length: nil}), do: scalar(type)
  defp field_value(%{type: type, array_length: n}), do: T.vector(n, scalar(type))

  defp message(module) do
    fields = module.__mavlink__(:fields)
    names = Enum.map(fields, & &1.name)
    map(T.fixed_list(Enum.map(fields, &field_value/1)), &struct!(module, Enum.zip(names, &1)))
  end

  defp any_message, do: bind(T.elements(APM.messages()), &message/1)

  # {sysid, compid, seq, compat_flags}
  defp header, do: {uint(8), uint(8), uint(8), T.frequency([{3, T.exactly(0)}, {1, uint(8)}])}

  # {key, link_id, timestamp}
  defp signer, do: {map(T.vector(32, uint(8)), &:erlang.list_to_binary/1), uint(8), map(uint(48), &max(&1, 1))}

  ## Generators: frames and streams

  # {message, header, compat_flags, kind}: kind is :v1 (ids < 256 only), :v2 or :signed.
  defp frame_spec(kinds \\ [:v1, :v2, :signed]) do
    map({any_message(), header(), T.elements(kinds)}, fn {%module{} = msg, {sysid, compid, seq, compat}, kind} ->
      kind = if kind == :v1 and module.__mavlink__(:id) > 255, do: :v2, else: kind
      {msg, [sysid: sysid, compid: compid, seq: seq], compat, kind}
    end)
  end

  # {bytes, the message they must decode to}
  defp encode_frame({msg, header, compat, kind}, signing) do
    case kind do
      :v1 -> {Frame.encode(msg, [version: 1] ++ header), without_extensions(msg)}
      :v2 -> {Frame.encode(msg, header ++ [compat_flags: compat]), msg}
      :signed -> {Frame.encode(msg, header ++ [compat_flags: compat, signing: signing]), msg}
    end
  end

  # A frame signed (when it is) with a random key and timestamp.
  defp frame(kinds \\ [:v1, :v2, :signed]) do
    map({frame_spec(kinds), signer()}, fn {spec, {key, link_id, ts}} ->
      encode_frame(spec, %{key: key, link_id: link_id, timestamp: ts})
    end)
  end

  # {stream, [{bytes, message}], [{offset, size}]}: frames, each behind what
  # `junk` generates, then @max_frame bytes without a magic byte, so that no
  # false candidate is still waiting for its bytes when the stream ends. Frames
  # are signed with @key, timestamps increasing. A stream in which a magic byte
  # outside the frames starts a CRC-valid known-id frame (whose signature, if
  # `verified?`, checks) is left out: that frame would be real, not junk.
  defp stream_of(junk, verified?) do
    gen =
      map({T.resize(8, T.list({junk, frame_spec()})), filler()}, fn {pairs, filler} ->
        {parts, {_, expected, ranges}} =
          Enum.map_reduce(Enum.with_index(pairs, 1), {0, [], []}, fn {{junk, spec}, ts}, {offset, expected, ranges} ->
            {bytes, msg} = encode_frame(spec, %{key: @key, link_id: 1, timestamp: ts})
            start = offset + byte_size(junk)
            {[junk, bytes], {start + byte_size(bytes), [{bytes, msg} | expected], [{start, byte_size(bytes)} | ranges]}}
          end)

        {IO.iodata_to_binary([parts, filler]), Enum.reverse(expected), ranges}
      end)

    T.add_constraint(gen, fn {stream, _, ranges} -> not hides_frame?(stream, ranges, verified?) end, true)
  end

  defp hides_frame?(stream, ranges, verified?) do
    stream
    |> :binary.matches([<<0xFD>>, <<0xFE>>])
    |> Enum.any?(fn {pos, 1} ->
      not Enum.any?(ranges, fn {start, size} -> pos >= start and pos < start + size end) and
        case Frame.decode(binary_part(stream, pos, byte_size(stream) - pos), @dialect) do
          {:ok, %Frame{message: %_{}, signature: nil}, _} ->
            true

          {:ok, %Frame{message: %_{}} = frame, _} ->
            not verified? or match?({:ok, _}, Signing.verify(Signing.new(key: @key, timestamp: 0), frame))

          _ ->
            false
        end
    end)
  end

  defp filler, do: bytes(non_magic(), @max_frame, @max_frame + 20)

  defp non_magic, do: T.elements(Enum.to_list(0..255) -- @magic)

  # A frame cut after its header. (Cut shorter, its candidate takes the rest of
  # its header, so perhaps an unknown id, from the next frame; right after a good
  # frame the parser is in sync, and would accept it, swallowing the next frame,
  # when its claimed end happened to be followed by a magic byte: the rule for
  # unknown ids, tested on its own above.)
  defp truncated_frame do
    bind(frame(), fn {<<magic, _::binary>> = bytes, _} ->
      header = if magic == 0xFE, do: 6, else: 10
      map(T.integer(header, byte_size(bytes) - 1), &binary_part(bytes, 0, &1))
    end)
  end

  # A frame with one byte changed.
  defp corrupted_frame do
    bind(frame(), fn {bytes, _} ->
      map({T.integer(0, byte_size(bytes) - 1), T.integer(1, 255)}, fn {i, x} ->
        replace_byte(bytes, i, bxor(:binary.at(bytes, i), x))
      end)
    end)
  end

  defp bytes(byte_gen, min, max),
    do: bind(T.integer(min, max), fn n -> map(T.vector(n, byte_gen), &:erlang.list_to_binary/1) end)

  defp garbage(:no_magic), do: bytes(non_magic(), 0, 40)
  defp garbage(:magic), do: bytes(T.frequency([{5, uint(8)}, {2, T.elements(@magic)}]), 0, 40)

  # Garbage that may hold magic bytes, then @max_frame or more bytes without one,
  # and no CRC-valid frame of a known id at any of its magic bytes.
  defp gap do
    gen = map({garbage(:magic), filler()}, fn {g, f} -> g <> f end)
    T.add_constraint(gen, &(not hides_known_frame?(&1)), true)
  end

  defp hides_known_frame?(bytes) do
    bytes
    |> :binary.matches([<<0xFD>>, <<0xFE>>])
    |> Enum.any?(fn {pos, 1} ->
      match?({:ok, %Frame{message: %_{}}, _}, Frame.decode(binary_part(bytes, pos, byte_size(bytes) - pos), @dialect))
    end)
  end

  # Random bytes with many magic bytes, whole frames (some signed with @key),
  # truncated and corrupted frames, and frames of unknown ids.
  defp noisy_stream do
    segment =
      T.frequency([
        {4, bytes(T.frequency([{6, uint(8)}, {1, T.elements(@magic)}]), 0, 200)},
        {2, map(frame(), &elem(&1, 0))},
        {1, map(own_key_frame(), &elem(&1, 0))},
        {1, bind(frame(), fn {bytes, _} -> map(T.integer(0, byte_size(bytes)), &binary_part(bytes, 0, &1)) end)},
        {1, truncated_frame()},
        {2, corrupted_frame()},
        {1, unknown_frame()}
      ])

    map(T.resize(20, T.list(segment)), &IO.iodata_to_binary/1)
  end

  defp own_key_frame do
    map({any_message(), uint(8), map(uint(12), &(&1 + 1))}, fn {msg, link_id, ts} ->
      {Frame.encode(msg, signing: %{key: @key, link_id: link_id, timestamp: ts}), msg}
    end)
  end

  # A well-formed MAVLink 2 frame of an id this dialect does not define (the CRC cannot be checked).
  defp unknown_frame do
    ids = map(uint(24), fn id -> if APM.message_info(id), do: 0xFFFFFF, else: id end)

    bind({ids, T.integer(0, 255)}, fn {id, len} ->
      map({bytes(uint(8), len, len), uint(16)}, fn {payload, crc} ->
        <<0xFD, len, 0, 0, 0, 1, 1, id::little-24, payload::binary, crc::16>>
      end)
    end)
  end

  defp replace_byte(bytes, i, b),
    do: <<binary_part(bytes, 0, i)::binary, b, binary_part(bytes, i + 1, byte_size(bytes) - i - 1)::binary>>

  # An unsigned frame with one bit flipped, never in the length byte (byte 1).
  defp flipped_frame do
    bind(frame([:v1, :v2]), fn {bytes, _} ->
      map(T.integer(0, 8 * (byte_size(bytes) - 1) - 1), fn bit ->
        bit = if bit >= 8, do: bit + 8, else: bit
        <<before::size(bit), b::1, rest::bitstring>> = bytes
        {<<before::size(bit), 1 - b::1, rest::bitstring>>, bytes}
      end)
    end)
  end

  # Chunk sizes to cut a stream into; what they do not cover is the last chunk.
  defp chunk_sizes, do: T.resize(30, T.list(T.frequency([{3, T.integer(1, 8)}, {2, T.integer(1, 400)}])))

  defp parser_signing do
    T.frequency([
      {2, T.exactly(nil)},
      {1, map(T.elements([:accept, :reject]), &Signing.new(key: @key, unsigned: &1, timestamp: 0))}
    ])
  end

  defp feed_chunks(parser, bytes, sizes) do
    {chunks, rest} =
      Enum.map_reduce(sizes, bytes, fn size, rest ->
        size = min(size, byte_size(rest))
        <<chunk::binary-size(size), rest::binary>> = rest
        {chunk, rest}
      end)

    {frames, parser} =
      Enum.reduce(chunks ++ [rest], {[], parser}, fn chunk, {acc, parser} ->
        {frames, parser} = Parser.feed(parser, chunk)
        {acc ++ frames, parser}
      end)

    {last, parser} = Parser.finish(parser)
    {frames ++ last, parser}
  end

  # The whole stream in one feed, then the end of the stream.
  defp feed_whole(parser, bytes) do
    {frames, parser} = Parser.feed(parser, bytes)
    {last, parser} = Parser.finish(parser)
    {frames ++ last, parser}
  end
end
