defmodule Dolphin.MAVLink.Frame do
  @moduledoc """
  MAVLink 1 and 2 framing: one frame in, one frame out.

  `decode/2` follows the decode vocabulary of the whole codec: it looks at the
  start of a buffer and returns

    * `{:ok, frame, rest}`: a frame whose checksum is right (or whose message id
      the dialect does not know: see below), and the bytes after it;
    * `{:more, buffer}`: the buffer holds the beginning of a frame; call again
      with more bytes appended;
    * `{:error, reason, rest}`: the start of the buffer is not a valid frame;
      `rest` is where to resume (the next magic byte, or the byte after a bad
      candidate's magic, so that a frame hidden inside a corrupted one is found).

  Reasons: `:garbage` (bytes before a magic byte), `:bad_incompat_flags` (a
  MAVLink 2 header with flags other than "signed", which nothing can parse),
  `:bad_crc`, `:unknown_id` (see below).

  A candidate with a message id the dialect does not define cannot have its
  checksum checked (its CRC_EXTRA is unknown), so by default it is refused
  like a bad checksum: `{:error, :unknown_id, rest}`, resuming one byte after
  its magic (what the MAVLink C library's parser amounts to). With
  `unknown: :forward` it is returned with `message: nil` and its raw bytes, for
  a router, but only when nothing else is likely: the stream is in sync
  (`in_sync: true`, the default; a parser says false after dropped bytes) and
  the bytes after it begin with a magic byte (or, with `at_end: true`, the
  data ends right after it; otherwise `{:more, buffer}` until the next byte
  comes). A caller that checks framing itself (a `.tlog` reader: a timestamp
  follows every frame) passes `unknown: :accept`.

  Decoding zero-fills a payload shorter than the message (MAVLink 2 truncation,
  MAVLink 1 frames without extension fields) and ignores bytes past it (fields
  of a newer definition). Encoding cuts MAVLink 1 payloads to the base fields
  and strips trailing zero bytes from MAVLink 2 payloads (keeping one).
  """

  import Bitwise, only: [|||: 2, <<<: 2]

  alias Dolphin.MAVLink.{CRC, Message, Value}

  @magic_v1 0xFE
  @magic_v2 0xFD
  @signed 0x01

  defstruct version: 2,
            sysid: 0,
            compid: 0,
            seq: 0,
            msgid: 0,
            incompat_flags: 0,
            compat_flags: 0,
            message: nil,
            payload: <<>>,
            signature: nil,
            raw: <<>>

  @typedoc "The signature block of a signed MAVLink 2 frame."
  @type signature :: %{link_id: byte(), timestamp: non_neg_integer(), signature: <<_::48>>}

  @type t :: %__MODULE__{
          version: 1 | 2,
          sysid: byte(),
          compid: byte(),
          seq: byte(),
          msgid: non_neg_integer(),
          incompat_flags: byte(),
          compat_flags: byte(),
          message: Message.t() | nil,
          payload: binary(),
          signature: signature() | nil,
          raw: binary()
        }

  @type error_reason :: :garbage | :bad_incompat_flags | :bad_crc | :unknown_id

  @typedoc "Header of a frame to encode, and its signing parameters for a signed MAVLink 2 frame."
  @type encode_opt ::
          {:version, 1 | 2}
          | {:sysid, byte()}
          | {:compid, byte()}
          | {:seq, byte()}
          | {:compat_flags, byte()}
          | {:signing, %{key: <<_::256>>, link_id: byte(), timestamp: non_neg_integer()}}

  @doc "Decodes the frame at the start of `buffer`; see the module doc."
  @spec decode(binary(), module(), keyword()) ::
          {:ok, t(), binary()} | {:more, binary()} | {:error, error_reason(), binary()}
  def decode(buffer, dialect, opts \\ []) do
    case decode_at(buffer, 0, decoder(dialect), opts) do
      {:ok, frame, next} -> {:ok, frame, from(buffer, next)}
      {:more, _at} -> {:more, buffer}
      {:error, reason, next} -> {:error, reason, from(buffer, next)}
    end
  end

  defp from(buffer, at), do: binary_part(buffer, at, byte_size(buffer) - at)

  @doc false
  # The dialect's look-up of a message id for decoding, as a function value:
  # calling it costs a local call, where `dialect.frame_decoder(id)` would look
  # the function up by name every time.
  @spec decoder(module()) :: (non_neg_integer() -> {byte(), non_neg_integer(), (binary() -> Message.t())} | nil)
  def decoder(dialect), do: Function.capture(dialect, :frame_decoder, 1)

  @doc false
  # decode/3 for a parser: looks at `buffer` from byte `at` and answers with
  # offsets instead of the rest of the buffer (`{:ok, frame, next}`, `{:more,
  # at}`, `{:error, reason, resume_at}`), since a sub-binary per frame costs as
  # much as decoding a small message. `decoder` comes from decoder/1.
  #
  # One binary match over the frame shapes, one struct per message and one per
  # frame, the checksum read from the buffer in place:
  # bench/codec.exs measures every term and binary made here.
  @spec decode_at(binary(), non_neg_integer(), function(), keyword()) ::
          {:ok, t(), non_neg_integer()} | {:more, non_neg_integer()} | {:error, error_reason(), non_neg_integer()}
  def decode_at(buf, at, decoder, opts) do
    case buf do
      <<_::binary-size(at), @magic_v2, len, 0, compat, seq, sysid, compid, msgid::little-24, payload::binary-size(len), crc::little-16, _::binary>> ->
        checked(buf, at, 12 + len, crc, payload, decoder, opts, 2, 0, compat, seq, sysid, compid, msgid, nil)

      <<_::binary-size(at), @magic_v2, len, @signed, compat, seq, sysid, compid, msgid::little-24, payload::binary-size(len), crc::little-16, link_id, timestamp::little-48, signature::binary-6,
        _::binary>> ->
        signature = %{link_id: link_id, timestamp: timestamp, signature: signature}
        checked(buf, at, 25 + len, crc, payload, decoder, opts, 2, @signed, compat, seq, sysid, compid, msgid, signature)

      <<_::binary-size(at), @magic_v2, _len, flags, _::binary>> when flags > @signed ->
        {:error, :bad_incompat_flags, at + 1}

      <<_::binary-size(at), @magic_v2, _::binary>> ->
        {:more, at}

      <<_::binary-size(at), @magic_v1, len, seq, sysid, compid, msgid, payload::binary-size(len), crc::little-16, _::binary>> ->
        checked(buf, at, 8 + len, crc, payload, decoder, opts, 1, 0, 0, seq, sysid, compid, msgid, nil)

      <<_::binary-size(at), @magic_v1, _::binary>> ->
        {:more, at}

      _ when at >= byte_size(buf) ->
        {:more, at}

      _ ->
        case :binary.match(buf, [<<@magic_v2>>, <<@magic_v1>>], scope: {at, byte_size(buf) - at}) do
          {pos, 1} -> {:error, :garbage, pos}
          :nomatch -> {:error, :garbage, byte_size(buf)}
        end
    end
  end

  # The checksum covers the bytes after the magic through the payload (the
  # header is 9 bytes in MAVLink 2, 5 in MAVLink 1), then the message's CRC_EXTRA.
  defp checked(buf, at, size, crc, payload, decoder, opts, version, flags, compat, seq, sysid, compid, msgid, signature) do
    len = byte_size(payload)

    case decoder.(msgid) do
      {crc_extra, max_len, decode} ->
        if CRC.checksum(buf, at + 1, if(version == 2, do: 9, else: 5) + len, crc_extra) == crc do
          message = decode_payload(decode, payload, len, max_len)
          raw = binary_part(buf, at, size)
          {:ok, new(__MODULE__, version, flags, compat, seq, sysid, compid, msgid, message, payload, signature, raw), at + size}
        else
          {:error, :bad_crc, at + 1}
        end

      nil ->
        unknown(buf, at, size, opts, version, flags, compat, seq, sysid, compid, msgid, payload, signature)
    end
  end

  # The struct is passed in, not written as %__MODULE__{}: with a literal
  # module the compiler folds it into a constant map that every frame then
  # updates key by key; built from variables, the map takes one allocation
  # with a shared key table. (The same holds for the generated message structs.)
  # Dolphin.MAVLink.Native builds its frames with it too.
  @doc false
  def new(struct, version, flags, compat, seq, sysid, compid, msgid, message, payload, signature, raw) do
    %{
      __struct__: struct,
      version: version,
      sysid: sysid,
      compid: compid,
      seq: seq,
      msgid: msgid,
      incompat_flags: flags,
      compat_flags: compat,
      message: message,
      payload: payload,
      signature: signature,
      raw: raw
    }
  end

  # Without CRC_EXTRA nothing vouches for an unknown frame but the framing itself:
  # when forwarding, trust it only right after a good frame and when the next
  # frame starts where its length says it ends. Until the byte after it is
  # there, wait (so that the result does not depend on where a stream was cut
  # into chunks), unless the caller says the data ends here.
  defp unknown(buf, at, size, opts, version, flags, compat, seq, sysid, compid, msgid, payload, signature) do
    next = at + size
    frame = fn -> new(__MODULE__, version, flags, compat, seq, sysid, compid, msgid, nil, payload, signature, binary_part(buf, at, size)) end

    case Keyword.get(opts, :unknown, :drop) do
      :accept ->
        {:ok, frame.(), next}

      :forward ->
        cond do
          not Keyword.get(opts, :in_sync, true) -> {:error, :unknown_id, at + 1}
          next == byte_size(buf) -> if Keyword.get(opts, :at_end, false), do: {:ok, frame.(), next}, else: {:more, at}
          :binary.at(buf, next) in [@magic_v1, @magic_v2] -> {:ok, frame.(), next}
          true -> {:error, :unknown_id, at + 1}
        end

      :drop ->
        {:error, :unknown_id, at + 1}
    end
  end

  defp decode_payload(decode, payload, len, max_len) when len == max_len, do: decode.(payload)

  # One construction (the sized first segment keeps it from being an append,
  # which would allocate a growable binary).
  defp decode_payload(decode, payload, len, max_len) when len < max_len,
    do: decode.(<<payload::binary-size(len), Value.zeros(max_len - len)::binary>>)

  defp decode_payload(decode, payload, _len, max_len), do: decode.(binary_part(payload, 0, max_len))

  @doc """
  Encodes a message into a complete frame.

  Options: `:version` (1 or 2, default 2), `:sysid`, `:compid`, `:seq` (default
  0), `:compat_flags` (MAVLink 2), and `:signing` (`%{key, link_id,
  timestamp}`, MAVLink 2 only) to sign it; `Dolphin.MAVLink.Signing` keeps
  timestamps increasing for a link. Raises `ArgumentError` for a field value
  that does not fit, or a message id above 255 in MAVLink 1.
  """
  @spec encode(Message.t(), [encode_opt()]) :: binary()
  def encode(%module{} = message, opts \\ []), do: encode(opts, module.__frame__(message), message, 2, 0, 0, 0, 0, nil)

  # The message module's `__frame__/1` gives `{id, crc_extra, min_len,
  # payload}` in one call (the struct's module is looked up once). The options
  # are walked into arguments (this is on the hot path of every frame sent), and
  # the frame is built in one construction that starts with a literal:
  # appending to a small binary (`<<bin::binary, ...>>`) would make it a
  # separately allocated writable binary, which costs more than the encoding.
  defp encode([], {id, crc_extra, min_len, payload}, message, version, sysid, compid, seq, compat, signing) do
    case version do
      2 ->
        flags = if signing, do: @signed, else: 0
        # The first seven bytes as one integer (its length byte is the
        # frame's to fill): each segment of a binary construction costs more
        # than the shifts. The frame is then built in one call.
        header = @magic_v2 ||| flags <<< 16 ||| compat <<< 24 ||| seq <<< 32 ||| sysid <<< 40 ||| compid <<< 48
        frame = CRC.frame_v2(header, id, payload, crc_extra)
        if signing, do: sign(frame, signing), else: frame

      1 when signing != nil ->
        raise ArgumentError, "MAVLink 1 frames cannot be signed"

      1 when id <= 255 ->
        body = <<min_len, seq, sysid, compid, id, payload::binary-size(min_len)>>
        <<@magic_v1, body::binary, CRC.checksum(body, 0, byte_size(body), crc_extra)::little-16>>

      1 ->
        raise ArgumentError, "#{Message.name(message)} (id #{id}) cannot travel as MAVLink 1: ids above 255 need MAVLink 2"
    end
  end

  defp encode([{:sysid, v} | t], p, m, ver, _, c, q, f, s) when v in 0..255, do: encode(t, p, m, ver, v, c, q, f, s)
  defp encode([{:compid, v} | t], p, m, ver, y, _, q, f, s) when v in 0..255, do: encode(t, p, m, ver, y, v, q, f, s)
  defp encode([{:seq, v} | t], p, m, ver, y, c, _, f, s) when v in 0..255, do: encode(t, p, m, ver, y, c, v, f, s)
  defp encode([{:version, v} | t], p, m, _, y, c, q, f, s) when v in [1, 2], do: encode(t, p, m, v, y, c, q, f, s)
  defp encode([{:compat_flags, v} | t], p, m, ver, y, c, q, _, s) when v in 0..255, do: encode(t, p, m, ver, y, c, q, v, s)
  defp encode([{:signing, nil} | t], p, m, ver, y, c, q, f, _), do: encode(t, p, m, ver, y, c, q, f, nil)

  defp encode([{:signing, %{key: <<_::binary-32>>, link_id: l, timestamp: ts} = s} | t], p, m, ver, y, c, q, f, _)
       when l in 0..255 and is_integer(ts) and ts >= 0 and ts < 0x1000000000000,
       do: encode(t, p, m, ver, y, c, q, f, s)

  defp encode([other | _], _p, _m, _ver, _y, _c, _q, _f, _s), do: raise(ArgumentError, "bad frame option: #{inspect(other)}")

  @doc """
  Appends a signature block to an encoded MAVLink 2 frame whose incompat flags
  already say "signed": link id, 48-bit timestamp (10 µs units since
  2015-01-01) and the first 6 bytes of SHA-256(key ‖ frame ‖ link id ‖ timestamp).
  """
  @spec sign(binary(), %{key: binary(), link_id: byte(), timestamp: non_neg_integer()}) :: binary()
  def sign(unsigned, %{key: key, link_id: link_id, timestamp: timestamp}) do
    block = <<link_id, timestamp::little-48>>
    <<signature::binary-6, _::binary>> = :crypto.hash(:sha256, [key, unsigned, block])
    IO.iodata_to_binary([unsigned, block, signature])
  end
end
