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
  def decode(buffer, dialect, opts \\ [])

  # One pattern per frame shape, matched in the function head, and one struct
  # built per frame: the fewer terms made per frame, the faster (bench/codec.exs).
  def decode(
        <<@magic_v2, len, 0, compat, seq, sysid, compid, msgid::little-24, payload::binary-size(len), crc::little-16,
          rest::binary>> = buf,
        dialect,
        opts
      ) do
    checked(buf, 12 + len, crc, payload, rest, dialect, opts, 2, 0, compat, seq, sysid, compid, msgid, nil)
  end

  def decode(
        <<@magic_v2, len, @signed, compat, seq, sysid, compid, msgid::little-24, payload::binary-size(len),
          crc::little-16, link_id, timestamp::little-48, signature::binary-6, rest::binary>> = buf,
        dialect,
        opts
      ) do
    signature = %{link_id: link_id, timestamp: timestamp, signature: signature}
    checked(buf, 25 + len, crc, payload, rest, dialect, opts, 2, @signed, compat, seq, sysid, compid, msgid, signature)
  end

  def decode(<<@magic_v2, _len, flags, _::binary>> = buf, _dialect, _opts) when flags > @signed,
    do: {:error, :bad_incompat_flags, binary_part(buf, 1, byte_size(buf) - 1)}

  def decode(<<@magic_v2, _::binary>> = buf, _dialect, _opts), do: {:more, buf}

  def decode(
        <<@magic_v1, len, seq, sysid, compid, msgid, payload::binary-size(len), crc::little-16, rest::binary>> = buf,
        dialect,
        opts
      ) do
    checked(buf, 8 + len, crc, payload, rest, dialect, opts, 1, 0, 0, seq, sysid, compid, msgid, nil)
  end

  def decode(<<@magic_v1, _::binary>> = buf, _dialect, _opts), do: {:more, buf}

  def decode(<<>>, _dialect, _opts), do: {:more, <<>>}

  def decode(buf, _dialect, _opts) do
    case :binary.match(buf, [<<@magic_v2>>, <<@magic_v1>>]) do
      {pos, 1} -> {:error, :garbage, binary_part(buf, pos, byte_size(buf) - pos)}
      :nomatch -> {:error, :garbage, <<>>}
    end
  end

  # The checksum covers the bytes after the magic through the payload (the
  # header is 9 bytes in MAVLink 2, 5 in MAVLink 1), then the message's CRC_EXTRA.
  defp checked(buf, size, crc, payload, rest, dialect, opts, version, flags, compat, seq, sysid, compid, msgid, sig) do
    len = byte_size(payload)
    crc_len = if version == 2, do: 9 + len, else: 5 + len

    case dialect.message_info(msgid) do
      {module, crc_extra, _min, max_len} ->
        if CRC.checksum(buf, 1, crc_len, crc_extra) == crc do
          message = decode_payload(module, payload, len, max_len)
          {:ok, new(version, flags, compat, seq, sysid, compid, msgid, message, payload, sig, binary_part(buf, 0, size)), rest}
        else
          bad_crc(buf)
        end

      nil ->
        unknown(buf, opts, fn ->
          {:ok, new(version, flags, compat, seq, sysid, compid, msgid, nil, payload, sig, binary_part(buf, 0, size)), rest}
        end)
    end
  end

  defp new(version, flags, compat, seq, sysid, compid, msgid, message, payload, signature, raw) do
    %__MODULE__{
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

  defp bad_crc(buf), do: {:error, :bad_crc, binary_part(buf, 1, byte_size(buf) - 1)}

  # Without CRC_EXTRA nothing vouches for an unknown frame but the framing itself:
  # when forwarding, trust it only right after a good frame and when the next
  # frame starts where its length says it ends. Until the byte after it is
  # there, wait (so that the result does not depend on where a stream was cut
  # into chunks), unless the caller says the data ends here.
  defp unknown(buf, opts, accept) do
    case Keyword.get(opts, :unknown, :drop) do
      :accept ->
        accept.()

      :forward ->
        {:ok, _frame, rest} = result = accept.()

        cond do
          not Keyword.get(opts, :in_sync, true) -> {:error, :unknown_id, binary_part(buf, 1, byte_size(buf) - 1)}
          rest == <<>> -> if Keyword.get(opts, :at_end, false), do: result, else: {:more, buf}
          framed?(rest) -> result
          true -> {:error, :unknown_id, binary_part(buf, 1, byte_size(buf) - 1)}
        end

      :drop ->
        {:error, :unknown_id, binary_part(buf, 1, byte_size(buf) - 1)}
    end
  end

  defp framed?(<<magic, _::binary>>), do: magic in [@magic_v1, @magic_v2]

  defp decode_payload(module, payload, len, max_len) when len == max_len, do: module.decode(payload)

  # One allocation; `<<payload::binary, ...>>` would be an append (see encode).
  defp decode_payload(module, payload, len, max_len) when len < max_len,
    do: module.decode(IO.iodata_to_binary([payload | Value.zeros(max_len - len)]))

  defp decode_payload(module, payload, _len, max_len), do: module.decode(binary_part(payload, 0, max_len))

  @doc """
  Encodes a message into a complete frame.

  Options: `:version` (1 or 2, default 2), `:sysid`, `:compid`, `:seq` (default
  0), `:compat_flags` (MAVLink 2), and `:signing` (`%{key, link_id,
  timestamp}`, MAVLink 2 only) to sign it; `Dolphin.MAVLink.Signing` keeps
  timestamps increasing for a link. Raises `ArgumentError` for a field value
  that does not fit, or a message id above 255 in MAVLink 1.
  """
  @spec encode(Message.t(), [encode_opt()]) :: binary()
  def encode(%_{} = message, opts \\ []), do: encode(opts, message, 2, 0, 0, 0, 0, nil)

  # The options are walked into arguments (this is on the hot path of every
  # frame sent), and the frame is built in one construction that starts with a
  # literal: appending to a small binary (`<<bin::binary, ...>>`) would make it
  # a separately allocated writable binary, which costs more than the encoding.
  defp encode([], %module{} = message, version, sysid, compid, seq, compat, signing) do
    {id, crc_extra, min_len} = module.__mavlink__(:frame)
    payload = module.encode(message)

    case version do
      2 ->
        payload = trim_zeros(payload, byte_size(payload))
        flags = if signing, do: @signed, else: 0
        body = <<byte_size(payload), flags, compat, seq, sysid, compid, id::little-24, payload::binary>>
        frame = <<@magic_v2, body::binary, CRC.checksum(body, 0, byte_size(body), crc_extra)::little-16>>
        if signing, do: sign(frame, signing), else: frame

      1 when signing != nil ->
        raise ArgumentError, "MAVLink 1 frames cannot be signed"

      1 when id <= 255 ->
        body = <<min_len, seq, sysid, compid, id, binary_part(payload, 0, min_len)::binary>>
        <<@magic_v1, body::binary, CRC.checksum(body, 0, byte_size(body), crc_extra)::little-16>>

      1 ->
        raise ArgumentError, "#{Message.name(message)} (id #{id}) cannot travel as MAVLink 1: ids above 255 need MAVLink 2"
    end
  end

  defp encode([{:sysid, v} | t], m, ver, _, c, q, f, s) when v in 0..255, do: encode(t, m, ver, v, c, q, f, s)
  defp encode([{:compid, v} | t], m, ver, y, _, q, f, s) when v in 0..255, do: encode(t, m, ver, y, v, q, f, s)
  defp encode([{:seq, v} | t], m, ver, y, c, _, f, s) when v in 0..255, do: encode(t, m, ver, y, c, v, f, s)
  defp encode([{:version, v} | t], m, _, y, c, q, f, s) when v in [1, 2], do: encode(t, m, v, y, c, q, f, s)
  defp encode([{:compat_flags, v} | t], m, ver, y, c, q, _, s) when v in 0..255, do: encode(t, m, ver, y, c, q, v, s)
  defp encode([{:signing, nil} | t], m, ver, y, c, q, f, _), do: encode(t, m, ver, y, c, q, f, nil)

  defp encode([{:signing, %{key: <<_::binary-32>>, link_id: l, timestamp: ts} = s} | t], m, ver, y, c, q, f, _)
       when l in 0..255 and is_integer(ts) and ts >= 0 and ts < 0x1000000000000,
       do: encode(t, m, ver, y, c, q, f, s)

  defp encode([other | _], _m, _ver, _y, _c, _q, _f, _s), do: raise(ArgumentError, "bad frame option: #{inspect(other)}")

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

  # MAVLink 2 drops trailing zero bytes of the payload, keeping at least one;
  # eight at a time first (extension fields are often all zero).
  defp trim_zeros(payload, n) when n > 8 do
    case payload do
      <<_::binary-size(n - 8), 0::64, _::binary>> -> trim_zeros(payload, n - 8)
      _ -> trim_ones(payload, n)
    end
  end

  defp trim_zeros(payload, n), do: trim_ones(payload, n)

  defp trim_ones(payload, 1), do: binary_part(payload, 0, 1)

  defp trim_ones(payload, n) do
    case payload do
      <<_::binary-size(n - 1), 0, _::binary>> -> trim_ones(payload, n - 1)
      _ -> binary_part(payload, 0, n)
    end
  end
end
