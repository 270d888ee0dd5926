defmodule Dolphin.MAVLink.Interop.PymavlinkTest do
  @moduledoc """
  A live interop round with the reference implementation, pymavlink 2.4.50
  (the project venv that scripts/bootstrap creates), through
  `test/interop/pymavlink_peer.py`:

    1. pymavlink encodes random messages (`generate`); we decode every frame to
       the same fields, verify the signatures, and re-encode MAVLink 2 frames
       byte for byte (MAVLink 1: pymavlink accepts our base-field frame);
    2. we encode random instances of every message of the dialect (MAVLink 2,
       signed, MAVLink 1 for ids < 256); pymavlink (`decode`) reads the same
       fields back.

  Records are compared as JSON (`Dolphin.MAVLink.Record` conventions), value
  by value, floats bit for bit (so `-0.0` is not `0.0`).
  """
  use ExUnit.Case, async: true

  @moduletag :interop
  @moduletag timeout: 300_000

  alias Dolphin.MAVLink.{Frame, JSON, Message, Record, Signing, Value}
  alias Dolphin.MAVLink.Ardupilotmega, as: APM

  @root Path.expand("../..", __DIR__)
  @python Path.join(@root, ".venv/bin/python")
  @peer Path.join(__DIR__, "pymavlink_peer.py")

  @key_hex "6c9a1f0e5b3d2c4a8f7e6d5c4b3a29181f2e3d4c5b6a79880f1e2d3c4b5a6978"
  @key Base.decode16!(@key_hex, case: :lower)
  @seed 20_241_121
  @count 2000

  @header_keys ~w(msg id mavlink signed sysid compid seq signing)

  setup_all do
    unless File.exists?(@python) do
      flunk("""
      the pymavlink venv is missing (#{@python}).
      Run scripts/bootstrap first (`make test` does): it creates .venv with pymavlink 2.4.50.
      """)
    end

    lines = peer!(["generate", "--seed", "#{@seed}", "--count", "#{@count}", "--key", @key_hex])

    assert length(lines) == @count,
           "pymavlink_peer.py generate printed #{length(lines)} records, expected #{@count}"

    records = Enum.map(lines, fn line -> {line, json!(line)} end)
    %{generated: records}
  end

  describe "pymavlink encodes, we decode" do
    test "every frame decodes to pymavlink's fields; MAVLink 2 frames re-encode byte for byte", %{
      generated: records
    } do
      assert records |> Enum.map(fn {_, r} -> r["msg"] end) |> Enum.uniq() |> length() ==
               length(APM.messages()),
             "generate should cover every message of the dialect"

      problems =
        records
        |> Enum.with_index()
        |> Enum.flat_map(fn {{line, rec}, i} ->
          check_pymavlink_frame(line, rec, "generated ##{i}")
        end)

      assert_none(problems, "disagreements with pymavlink-encoded frames")
    end

    test "our MAVLink 1 frames of the same messages: base fields as sent, pymavlink decodes them alike",
         %{generated: records} do
      v1 =
        for {{_line, %{"mavlink" => 1} = rec}, i} <- Enum.with_index(records),
            do: {rec, "generated ##{i}"}

      assert length(v1) > 100

      {cases, problems} =
        Enum.map_reduce(v1, [], fn {rec, label}, problems ->
          theirs = Base.decode16!(rec["frame"], case: :lower)

          assert {:ok, %Frame{message: message}, <<>>} = Frame.decode(theirs, APM),
                 "#{label} #{rec["msg"]}: we cannot decode pymavlink's frame #{rec["frame"]}"

          %module{} = message
          label = "#{label} #{rec["msg"]} (id #{rec["id"]}, MAVLink 1, #{rec["profile"]})"

          ours =
            Frame.encode(message,
              version: 1,
              sysid: rec["sysid"],
              compid: rec["compid"],
              seq: rec["seq"]
            )

          expected =
            %{rec | "fields" => zero_extensions(module, rec["fields"])}
            |> Map.drop(["frame", "profile"])

          # Same header (but the length) and the same base-field bytes as pymavlink's frame.
          min_len = module.__mavlink__(:min_len)
          <<0xFE, _their_len, their_header::binary-4, their_payload::binary>> = theirs
          <<0xFE, our_len, our_header::binary-4, our_payload::binary>> = ours

          byte_problems =
            cond do
              our_len != min_len ->
                ["#{label}: our length byte is #{our_len}, expected min_len #{min_len}"]

              our_header != their_header ->
                [
                  "#{label}: header #{hex(our_header)} differs from pymavlink's #{hex(their_header)}"
                ]

              binary_part(our_payload, 0, min_len) != binary_part(their_payload, 0, min_len) ->
                ["#{label}: base payload differs: #{first_diff(ours, theirs)}"]

              true ->
                []
            end

          # Our own decoder reads our v1 frame back to the same values.
          {:ok, back, <<>>} = Frame.decode(ours, APM)

          self_problems =
            diff_records(
              label <> " (our decoder on our frame)",
              record_json(back),
              expected,
              "ours",
              "expected"
            )

          {{ours, expected, label}, problems ++ byte_problems ++ self_problems}
        end)

      decoded = pymavlink_decode(Enum.map(cases, fn {ours, _, _} -> ours end), nil)

      problems =
        problems ++
          Enum.flat_map(Enum.zip(cases, decoded), fn {{ours, expected, label}, theirs} ->
            compare_with_pymavlink(label, ours, expected, theirs)
          end)

      assert_none(problems, "disagreements on our MAVLink 1 frames")
    end
  end

  describe "we encode, pymavlink decodes" do
    test "random instances of every message (MAVLink 2, signed, MAVLink 1): pymavlink reads the same fields" do
      :rand.seed(:exsss, {@seed, 301, 2})
      modules = APM.messages()
      assert length(modules) == 301

      profiles = [:zero, :max, :min, :random, :random, :sparse]
      modes = [:v2, :signed, :v1]

      cases =
        for {module, m} <- Enum.with_index(modules), {profile, j} <- Enum.with_index(profiles) do
          id = module.__mavlink__(:id)
          mode = Enum.at(modes, rem(m + j, 3))
          mode = if mode == :v1 and id > 255, do: :v2, else: mode
          values = for f <- module.__mavlink__(:fields), do: {f.name, random_value(f, profile)}
          {:ok, message} = Message.new(module, values)
          header = [sysid: rand_byte(), compid: rand_byte(), seq: rand_byte()]

          bytes =
            case mode do
              :v2 ->
                Frame.encode(message, [version: 2] ++ header)

              :v1 ->
                Frame.encode(message, [version: 1] ++ header)

              :signed ->
                now = Enum.random([1, 2, 0xFFFF_FFFF_FFFF, :rand.uniform(0xFFFF_FFFF_FFFF)])
                signer = Signing.new(key: @key, link_id: rand_byte(), timestamp: 0)
                {bytes, _signer} = Signing.encode(signer, message, header ++ [now: now])
                bytes
            end

          label = "ours #{Message.name(message)} (id #{id}, #{mode}, #{profile})"
          {bytes, message, mode, label}
        end

      assert cases |> Enum.map(fn {_, %mod{}, _, _} -> mod end) |> Enum.uniq() |> length() == 301

      # What we expect pymavlink to read: what our decoder reads, once that is
      # checked against the message we encoded (extension fields zero in MAVLink 1).
      {expected, problems} =
        Enum.map_reduce(cases, [], fn {bytes, %module{} = message, mode, label}, problems ->
          assert {:ok, frame, <<>>} = Frame.decode(bytes, APM),
                 "#{label}: we cannot decode our own frame #{hex(bytes)}"

          ours = record_json(frame)
          sent = json!(Record.encode(%{frame | message: message}))["fields"]
          sent = if mode == :v1, do: zero_extensions(module, sent), else: sent

          self_problems =
            diff_fields(
              label <> " (our decoder on our frame)",
              module,
              ours["fields"],
              sent,
              "decoded",
              "sent"
            )

          {ours, problems ++ self_problems}
        end)

      assert_none(problems, "round-trip failures of our own codec")

      decoded = pymavlink_decode(Enum.map(cases, &elem(&1, 0)), @key)

      problems =
        [cases, expected, decoded]
        |> Enum.zip()
        |> Enum.flat_map(fn {{bytes, _msg, _mode, label}, ours, theirs} ->
          compare_with_pymavlink(label, bytes, ours, theirs)
        end)

      assert_none(problems, "disagreements: pymavlink decoding our frames")
    end

    test "the decode peer rejects what it must (bad CRC, wrong signing key)" do
      message = %APM.Heartbeat{type: 2, autopilot: 3, custom_mode: 7}
      good = Frame.encode(message, sysid: 1, compid: 1)
      v1 = Frame.encode(message, version: 1, sysid: 1, compid: 1)

      {signed, _} =
        Signing.encode(Signing.new(key: @key, link_id: 1, timestamp: 0), message, sysid: 1, now: 1000)

      {other_key, _} =
        Signing.encode(Signing.new(key: :binary.copy(<<1>>, 32), link_id: 1, timestamp: 0), message,
          sysid: 1,
          now: 1000
        )

      flip_last = fn bin ->
        binary_part(bin, 0, byte_size(bin) - 1) <> <<Bitwise.bxor(:binary.last(bin), 1)>>
      end

      flip_crc = fn bin ->
        binary_part(bin, 0, byte_size(bin) - 2) <>
          <<Bitwise.bxor(:binary.at(bin, byte_size(bin) - 2), 0x80)>> <>
          binary_part(bin, byte_size(bin) - 1, 1)
      end

      [ok1, ok2, ok3, bad1, bad2, bad3, bad4] =
        pymavlink_decode(
          [good, v1, signed, flip_crc.(good), flip_crc.(v1), flip_last.(signed), other_key],
          @key
        )

      for ok <- [ok1, ok2, ok3],
          do: assert(%{"msg" => "HEARTBEAT", "fields" => %{"custom_mode" => 7}} = ok)

      assert ok3["signing"] == %{"secret_key" => @key_hex, "link_id" => 1, "timestamp" => 1000}

      for bad <- [bad1, bad2, bad3, bad4],
          do:
            assert(
              %{"error" => _} = bad,
              "pymavlink should reject this frame, got #{inspect(bad)}"
            )
    end
  end

  ## Checking one pymavlink frame

  defp check_pymavlink_frame(line, rec, label) do
    bytes = Base.decode16!(rec["frame"], case: :lower)

    label =
      "#{label} #{rec["msg"]} (id #{rec["id"]}, MAVLink #{rec["mavlink"]}#{if rec["signed"], do: " signed"}, #{rec["profile"]})"

    case Frame.decode(bytes, APM) do
      {:ok, %Frame{message: nil}, _rest} ->
        ["#{label}: we do not know message id #{rec["id"]}"]

      {:ok, frame, <<>>} ->
        expected = Map.drop(rec, ["frame", "profile"])

        signature_problems(frame, rec, label) ++
          diff_records(label, record_json(frame), expected, "ours", "pymavlink") ++
          reencode_problems(frame, line, rec, bytes, label)

      {:ok, _frame, rest} ->
        ["#{label}: #{byte_size(rest)} bytes left after the frame"]

      other ->
        [
          "#{label}: our decoder rejects pymavlink's frame #{rec["frame"]}: #{inspect(other, limit: 5)}"
        ]
    end
  end

  defp signature_problems(%Frame{signature: nil}, %{"signed" => false}, _label), do: []

  defp signature_problems(%Frame{signature: nil}, _rec, label),
    do: ["#{label}: signed per pymavlink, but we see no signature"]

  defp signature_problems(frame, rec, label) do
    ok =
      case Signing.verify(Signing.new(key: @key, timestamp: 0), frame) do
        {:ok, _} ->
          []

        {:error, why, _} ->
          ["#{label}: Signing.verify rejects pymavlink's signature: #{inspect(why)}"]
      end

    wrong =
      case Signing.verify(Signing.new(key: :binary.copy(<<0>>, 32)), frame) do
        {:error, :bad_signature, _} ->
          []

        other ->
          [
            "#{label}: Signing.verify accepts the frame with a wrong key: #{inspect(other, limit: 3)}"
          ]
      end

    header =
      if rec["signing"]["link_id"] == frame.signature.link_id and
           rec["signing"]["timestamp"] == frame.signature.timestamp,
         do: [],
         else: [
           "#{label}: signature block #{inspect(frame.signature)} vs pymavlink's #{inspect(rec["signing"])}"
         ]

    ok ++ wrong ++ header
  end

  defp reencode_problems(%Frame{version: 1}, _line, _rec, _bytes, _label), do: []

  defp reencode_problems(frame, line, _rec, bytes, label) do
    signing =
      case frame.signature do
        nil -> []
        sig -> [signing: %{key: @key, link_id: sig.link_id, timestamp: sig.timestamp}]
      end

    ours =
      Frame.encode(
        frame.message,
        [version: 2, sysid: frame.sysid, compid: frame.compid, seq: frame.seq] ++ signing
      )

    from_record =
      case Record.decode(line, APM) do
        {:ok, message, opts} -> Frame.encode(message, opts)
        {:error, e} -> {:error, Exception.message(e)}
      end

    [
      {ours, "re-encoding our decoded message"},
      {from_record, "encoding pymavlink's JSON record (Record.decode/2)"}
    ]
    |> Enum.flat_map(fn
      {^bytes, _what} ->
        []

      {{:error, why}, what} ->
        ["#{label}: #{what} failed: #{why}"]

      {other, what} ->
        ["#{label}: #{what} does not reproduce pymavlink's frame: #{first_diff(other, bytes)}"]
    end)
  end

  # Compares pymavlink's reading of one of our frames with what we expect.
  defp compare_with_pymavlink(label, bytes, expected, %{"error" => why}),
    do: [
      "#{label}: pymavlink rejects our frame #{hex(bytes)}: #{why} (we expected #{inspect(expected["fields"], limit: 8)})"
    ]

  defp compare_with_pymavlink(label, _bytes, expected, theirs),
    do: diff_records(label, expected, theirs, "ours", "pymavlink")

  ## Record comparison

  defp record_json(%Frame{signature: nil} = frame), do: json!(Record.encode(frame))
  defp record_json(frame), do: json!(Record.encode(frame, key: @key))

  defp diff_records(label, a, b, a_name, b_name) do
    header =
      for key <- @header_keys, not same?(Map.get(a, key), Map.get(b, key)) do
        "#{label}: #{key}: #{a_name} #{inspect(Map.get(a, key))}, #{b_name} #{inspect(Map.get(b, key))}"
      end

    case {APM.message_module(a["msg"] || ""), header} do
      {nil, _} -> header ++ ["#{label}: unknown message name #{inspect(a["msg"])}"]
      {module, []} -> diff_fields(label, module, a["fields"], b["fields"], a_name, b_name)
      {_module, header} -> header
    end
  end

  defp diff_fields(label, module, a, b, a_name, b_name) do
    names = Enum.map(module.__mavlink__(:fields), &Atom.to_string(&1.name))
    extra = (Map.keys(a || %{}) ++ Map.keys(b || %{})) |> Enum.uniq() |> Kernel.--(names)

    field_problems =
      for name <- names,
          {field, va, vb} <-
            field_diffs(name, Map.fetch(a || %{}, name), Map.fetch(b || %{}, name)) do
        "#{label}: field #{field}: #{a_name} #{show(va)}, #{b_name} #{show(vb)}"
      end

    field_problems ++ for(name <- extra, do: "#{label}: unexpected field #{inspect(name)}")
  end

  # Arrays of the same length differ element by element: name the elements (at most 5).
  defp field_diffs(name, {:ok, [_ | _] = a}, {:ok, [_ | _] = b}) when length(a) == length(b) do
    diffs =
      for {{x, y}, i} <- Enum.with_index(Enum.zip(a, b)),
          not same?(x, y),
          do: {"#{name}[#{i}]", {:ok, x}, {:ok, y}}

    Enum.take(diffs, 5) ++
      if(length(diffs) > 5,
        do: [{"#{name}", {:ok, "(#{length(diffs) - 5} more elements differ)"}, {:ok, "..."}}],
        else: []
      )
  end

  defp field_diffs(name, a, b), do: if(same?(a, b), do: [], else: [{name, a, b}])

  defp show({:ok, v}), do: inspect(v, limit: :infinity, printable_limit: 300)
  defp show(:error), do: "(missing)"

  # Exact equality, floats by bits: -0.0 is not 0.0 (OTP 25 says they are ==, and they match each other).
  defp same?(a, b) when is_float(a) and is_float(b), do: <<a::float-64>> == <<b::float-64>>
  defp same?([a | as], [b | bs]), do: same?(a, b) and same?(as, bs)
  defp same?({:ok, a}, {:ok, b}), do: same?(a, b)

  defp same?(%{} = a, %{} = b),
    do:
      Enum.sort(Map.keys(a)) == Enum.sort(Map.keys(b)) and
        Enum.all?(a, fn {k, v} -> same?(v, Map.fetch!(b, k)) end)

  defp same?(a, b), do: a === b

  defp zero_extensions(module, fields) do
    Enum.reduce(module.__mavlink__(:fields), fields, fn
      %{extension: true, name: name, type: type, array_length: n}, acc ->
        Map.put(acc, Atom.to_string(name), Value.zero(type, n))

      _, acc ->
        acc
    end)
  end

  defp assert_none([], _what), do: :ok

  defp assert_none(problems, what) do
    shown = Enum.take(problems, 40)
    more = if length(problems) > 40, do: "\n... and #{length(problems) - 40} more", else: ""
    flunk("#{length(problems)} #{what}:\n" <> Enum.join(shown, "\n") <> more)
  end

  ## Random values (every value exactly representable: float fields hold float32 values)

  defp random_value(%{type: :char, array_length: n}, profile) do
    n = n || 1

    len =
      case profile do
        :zero -> 0
        p when p in [:max, :min] -> n
        _ -> Enum.random([0, n, :rand.uniform(n + 1) - 1])
      end

    for _ <- 1..len//1, into: "", do: <<0x1F + :rand.uniform(0x7F - 0x20)>>
  end

  defp random_value(%{array_length: nil, type: type}, profile),
    do: random_scalar(type, field_profile(profile))

  defp random_value(%{array_length: n, type: type}, profile) do
    values = for _ <- 1..n, do: random_scalar(type, field_profile(profile))

    if profile == :sparse and :rand.uniform(2) == 1 do
      cut = :rand.uniform(n + 1) - 1
      Enum.take(values, cut) ++ List.duplicate(Value.zero(type, nil), n - cut)
    else
      values
    end
  end

  defp field_profile(:sparse), do: Enum.random([:zero, :random])
  defp field_profile(profile), do: profile

  defp random_scalar(type, profile) when type in [:float, :double] do
    single = type == :float

    case profile do
      :zero ->
        0.0

      :max ->
        Enum.random(
          if single,
            do: [f32(0x7F7FFFFF), :infinity, :nan, f32(0x7E967699)],
            else: [f64(0x7FEFFFFFFFFFFFFF), :infinity, :nan, 1.0e308]
        )

      :min ->
        Enum.random(
          if single,
            do: [f32(0xFF7FFFFF), :neg_infinity, f32(0x80000001), f32(0x80000000)],
            else: [
              f64(0xFFEFFFFFFFFFFFFF),
              :neg_infinity,
              f64(0x8000000000000001),
              f64(0x8000000000000000)
            ]
        )

      :random ->
        random_float(single)
    end
  end

  defp random_scalar(type, profile) do
    {lo, hi} = Value.int_range(type)

    case profile do
      :zero ->
        0

      :max ->
        hi

      :min ->
        lo

      :random ->
        case :rand.uniform(5) do
          1 -> Enum.random([lo, hi, 0, 1, hi - 1, lo + 1])
          2 -> max(lo, min(hi, :rand.uniform(2001) - 1001))
          _ -> lo + :rand.uniform(hi - lo + 1) - 1
        end
    end
  end

  defp random_float(single) do
    case :rand.uniform(4) do
      1 ->
        if single,
          do:
            Enum.random([
              f32(0x80000000),
              :nan,
              :infinity,
              :neg_infinity,
              f32(0x7F7FFFFF),
              f32(0xFF7FFFFF),
              f32(0x00800000),
              f32(0x00000001),
              f32(0x807FFFFF),
              f32(0x3F800000),
              {:nan, 0x7FC00001},
              {:nan, 0xFFC00000}
            ]),
          else:
            Enum.random([
              f64(0x8000000000000000),
              :nan,
              :infinity,
              :neg_infinity,
              f64(0x7FEFFFFFFFFFFFFF),
              f64(0x0000000000000001),
              f64(0x800FFFFFFFFFFFFF),
              f64(0x0010000000000000),
              {:nan, 0x7FF8000000000001},
              {:nan, 0xFFF8000000000000}
            ])

      2 ->
        # An ordinary value, float32-rounded for float fields.
        x = (:rand.uniform() - 0.5) * 2000.0

        if single,
          do:
            (
              <<y::float-32>> = <<x::float-32>>
              y
            ),
          else: x

      _ ->
        random_bits(single)
    end
  end

  # A finite value from random bits: every exponent, subnormals included.
  defp random_bits(true) do
    bits = :rand.uniform(0x1_0000_0000) - 1
    if Bitwise.band(bits, 0x7F800000) == 0x7F800000, do: random_bits(true), else: f32(bits)
  end

  defp random_bits(false) do
    bits = :rand.uniform(0x1_0000_0000_0000_0000) - 1

    if Bitwise.band(bits, 0x7FF0000000000000) == 0x7FF0000000000000,
      do: random_bits(false),
      else: f64(bits)
  end

  # Floats from bits at run time (the compiler would fold a literal -0.0 into 0.0).
  defp f32(bits),
    do:
      (
        <<f::float-32>> = <<bits::32>>
        f
      )

  defp f64(bits),
    do:
      (
        <<f::float-64>> = <<bits::64>>
        f
      )

  defp rand_byte, do: :rand.uniform(256) - 1

  ## The Python peer

  defp peer!(args, input \\ nil) do
    {cmd, cmd_args, env} =
      case input do
        nil ->
          {@python, [@peer | args], []}

        path ->
          {"/bin/sh", ["-c", ~s(exec "$0" "$@" < "$PEER_INPUT"), @python, @peer | args],
           [{"PEER_INPUT", path}]}
      end

    {out, status} =
      System.cmd(cmd, cmd_args,
        env: [{"MAV_IGNORE_CRC", nil} | env],
        stderr_to_stdout: true,
        cd: @root
      )

    if status != 0 do
      flunk("""
      pymavlink_peer.py #{Enum.join(args, " ")} exited with status #{status}:
      #{String.slice(out, -3000, 3000)}
      (is the venv complete? scripts/bootstrap installs pymavlink 2.4.50; `make test` runs it)
      """)
    end

    String.split(out, "\n", trim: true)
  end

  # Decodes frames with pymavlink: one JSON record (or {"error": ...}) per frame.
  defp pymavlink_decode(frames, key) do
    path =
      Path.join(System.tmp_dir!(), "dolphin_pymavlink_#{System.unique_integer([:positive])}.hex")

    File.write!(path, Enum.map(frames, &[hex(&1), ?\n]))

    try do
      args = if key, do: ["decode", "--key", Base.encode16(key, case: :lower)], else: ["decode"]
      lines = peer!(args, path)

      assert length(lines) == length(frames),
             "pymavlink_peer.py decode printed #{length(lines)} lines for #{length(frames)} frames"

      Enum.map(lines, &json!/1)
    after
      File.rm(path)
    end
  end

  defp json!(iodata) do
    case JSON.decode(IO.iodata_to_binary(iodata)) do
      {:ok, value} ->
        value

      {:error, e} ->
        flunk("bad JSON (#{Exception.message(e)}): #{String.slice(IO.iodata_to_binary(iodata), 0, 300)}")
    end
  end

  defp hex(bin), do: Base.encode16(bin, case: :lower)

  defp first_diff(a, b) do
    at =
      Enum.find(0..max(byte_size(a), byte_size(b)), fn i ->
        i >= byte_size(a) or i >= byte_size(b) or :binary.at(a, i) != :binary.at(b, i)
      end)

    "first difference at byte #{at} (#{byte_size(a)} vs #{byte_size(b)} bytes)\n    ours:      #{hex(a)}\n    pymavlink: #{hex(b)}"
  end
end
