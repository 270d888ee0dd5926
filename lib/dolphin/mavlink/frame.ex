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
  `:bad_crc`.

  A frame with an id the dialect does not define cannot have its checksum
  checked (its CRC_EXTRA is unknown). It is returned with `message: nil` and
  its raw bytes, so that a router can forward it, when the stream is in sync
  (option `in_sync`, default true; a parser sets it false after dropped bytes)
  and the bytes after it begin with a magic byte (or, with `at_end: true`, the
  data ends right after it; otherwise `{:more, buffer}` until the next byte
  comes). Otherwise it is treated as garbage: a random magic byte inside noise
  must not swallow the frames after it.

  Decoding zero-fills a payload shorter than the message (MAVLink 2 truncation,
  MAVLink 1 frames without extension fields) and ignores bytes past it (fields
  of a newer definition). Encoding cuts MAVLink 1 payloads to the base fields
  and strips trailing zero bytes from MAVLink 2 payloads (keeping one).
  """

  import Bitwise

  alias Dolphin.MAVLink.{CRC, Message}

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

  @type error_reason :: :garbage | :bad_incompat_flags | :bad_crc

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

  def decode(<<@magic_v2, len, flags, compat, seq, sysid, compid, msgid::little-24, _::binary>> = buf, dialect, opts)
      when (flags &&& bnot(@signed)) == 0 do
    total = 12 + len + (flags &&& @signed) * 13

    case buf do
      <<frame::binary-size(total), rest::binary>> ->
        <<_, header_payload::binary-size(9 + len), crc::little-16, sig::binary>> = frame

        case dialect.message_info(msgid) do
          {module, crc_extra, _min, max_len} ->
            if CRC.accumulate_byte(crc_extra, CRC.accumulate(header_payload, 0xFFFF)) == crc do
              payload = binary_part(header_payload, 9, len)

              {:ok,
               %__MODULE__{
                 version: 2,
                 sysid: sysid,
                 compid: compid,
                 seq: seq,
                 msgid: msgid,
                 incompat_flags: flags,
                 compat_flags: compat,
                 message: decode_payload(module, payload, len, max_len),
                 payload: payload,
                 signature: signature(sig),
                 raw: frame
               }, rest}
            else
              bad_crc(buf)
            end

          nil ->
            unknown(buf, opts, fn ->
              {:ok,
               %__MODULE__{
                 version: 2,
                 sysid: sysid,
                 compid: compid,
                 seq: seq,
                 msgid: msgid,
                 incompat_flags: flags,
                 compat_flags: compat,
                 payload: binary_part(header_payload, 9, len),
                 signature: signature(sig),
                 raw: frame
               }, rest}
            end)
        end

      _short ->
        {:more, buf}
    end
  end

  def decode(<<@magic_v2, _len, flags, _::binary>> = buf, _dialect, _opts) when (flags &&& bnot(@signed)) != 0,
    do: {:error, :bad_incompat_flags, binary_part(buf, 1, byte_size(buf) - 1)}

  def decode(<<@magic_v2, _::binary>> = buf, _dialect, _opts) when byte_size(buf) < 10, do: {:more, buf}

  def decode(<<@magic_v1, len, seq, sysid, compid, msgid, _::binary>> = buf, dialect, opts) do
    total = 8 + len

    case buf do
      <<frame::binary-size(total), rest::binary>> ->
        <<_, header_payload::binary-size(5 + len), crc::little-16>> = frame

        case dialect.message_info(msgid) do
          {module, crc_extra, _min, max_len} ->
            if CRC.accumulate_byte(crc_extra, CRC.accumulate(header_payload, 0xFFFF)) == crc do
              payload = binary_part(header_payload, 5, len)

              {:ok,
               %__MODULE__{
                 version: 1,
                 sysid: sysid,
                 compid: compid,
                 seq: seq,
                 msgid: msgid,
                 message: decode_payload(module, payload, len, max_len),
                 payload: payload,
                 raw: frame
               }, rest}
            else
              bad_crc(buf)
            end

          nil ->
            unknown(buf, opts, fn ->
              {:ok,
               %__MODULE__{
                 version: 1,
                 sysid: sysid,
                 compid: compid,
                 seq: seq,
                 msgid: msgid,
                 payload: binary_part(header_payload, 5, len),
                 raw: frame
               }, rest}
            end)
        end

      _short ->
        {:more, buf}
    end
  end

  def decode(<<@magic_v1, _::binary>> = buf, _dialect, _opts) when byte_size(buf) < 6, do: {:more, buf}

  def decode(<<>>, _dialect, _opts), do: {:more, <<>>}

  def decode(buf, _dialect, _opts) do
    case :binary.match(buf, [<<@magic_v2>>, <<@magic_v1>>]) do
      {pos, 1} -> {:error, :garbage, binary_part(buf, pos, byte_size(buf) - pos)}
      :nomatch -> {:error, :garbage, <<>>}
    end
  end

  defp bad_crc(buf), do: {:error, :bad_crc, binary_part(buf, 1, byte_size(buf) - 1)}

  # Without CRC_EXTRA nothing vouches for an unknown frame but the framing itself:
  # trust it only right after a good frame and when the next frame starts where
  # its length says it ends. Until the byte after it is there, wait (so that the
  # result does not depend on where a stream was cut into chunks), unless the
  # caller says the data ends here (`at_end: true`, e.g. a whole datagram).
  defp unknown(buf, opts, accept) do
    {:ok, _frame, rest} = result = accept.()

    cond do
      not Keyword.get(opts, :in_sync, true) -> {:error, :garbage, binary_part(buf, 1, byte_size(buf) - 1)}
      rest == <<>> -> if Keyword.get(opts, :at_end, false), do: result, else: {:more, buf}
      framed?(rest) -> result
      true -> {:error, :garbage, binary_part(buf, 1, byte_size(buf) - 1)}
    end
  end

  defp framed?(<<magic, _::binary>>), do: magic in [@magic_v1, @magic_v2]

  defp signature(<<>>), do: nil

  defp signature(<<link_id, timestamp::little-48, signature::binary-6>>),
    do: %{link_id: link_id, timestamp: timestamp, signature: signature}

  defp decode_payload(module, payload, len, max_len) when len == max_len, do: module.decode(payload)

  defp decode_payload(module, payload, len, max_len) when len < max_len,
    do: module.decode(<<payload::binary, 0::size((max_len - len) * 8)>>)

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
  def encode(%module{} = message, opts \\ []) do
    {id, crc_extra, min_len} = module.__mavlink__(:frame)
    payload = module.encode(message)

    case encode_opts(opts, {2, 0, 0, 0, 0, nil}) do
      {2, sysid, compid, seq, compat, signing} ->
        payload = trim_zeros(payload, byte_size(payload))
        flags = if signing, do: @signed, else: 0
        body = <<byte_size(payload), flags, compat, seq, sysid, compid, id::little-24, payload::binary>>
        unsigned = <<@magic_v2, body::binary, checksum(body, crc_extra)::little-16>>
        if signing, do: sign(unsigned, signing), else: unsigned

      {1, sysid, compid, seq, _compat, nil} when id <= 255 ->
        body = <<min_len, seq, sysid, compid, id, binary_part(payload, 0, min_len)::binary>>
        <<@magic_v1, body::binary, checksum(body, crc_extra)::little-16>>

      {1, _, _, _, _, nil} ->
        raise ArgumentError, "#{Message.name(message)} (id #{id}) cannot travel as MAVLink 1: ids above 255 need MAVLink 2"

      {1, _, _, _, _, _signing} ->
        raise ArgumentError, "MAVLink 1 frames cannot be signed"
    end
  end

  # One pass over the options (this is on the hot path of every frame sent).
  defp encode_opts([], acc), do: acc
  defp encode_opts([{:version, v} | t], acc) when v in [1, 2], do: encode_opts(t, put_elem(acc, 0, v))
  defp encode_opts([{:sysid, v} | t], acc) when v in 0..255, do: encode_opts(t, put_elem(acc, 1, v))
  defp encode_opts([{:compid, v} | t], acc) when v in 0..255, do: encode_opts(t, put_elem(acc, 2, v))
  defp encode_opts([{:seq, v} | t], acc) when v in 0..255, do: encode_opts(t, put_elem(acc, 3, v))
  defp encode_opts([{:compat_flags, v} | t], acc) when v in 0..255, do: encode_opts(t, put_elem(acc, 4, v))
  defp encode_opts([{:signing, nil} | t], acc), do: encode_opts(t, put_elem(acc, 5, nil))

  defp encode_opts([{:signing, %{key: <<_::binary-32>>, link_id: l, timestamp: ts} = s} | t], acc)
       when l in 0..255 and is_integer(ts) and ts >= 0 and ts < 0x1000000000000,
       do: encode_opts(t, put_elem(acc, 5, s))

  defp encode_opts([other | _], _acc), do: raise(ArgumentError, "bad frame option: #{inspect(other)}")

  @doc """
  Appends a signature block to an encoded MAVLink 2 frame whose incompat flags
  already say "signed": link id, 48-bit timestamp (10 µs units since
  2015-01-01) and the first 6 bytes of SHA-256(key ‖ frame ‖ link id ‖ timestamp).
  """
  @spec sign(binary(), %{key: binary(), link_id: byte(), timestamp: non_neg_integer()}) :: binary()
  def sign(unsigned, %{key: key, link_id: link_id, timestamp: timestamp}) do
    signed = <<unsigned::binary, link_id, timestamp::little-48>>
    <<signature::binary-6, _::binary>> = :crypto.hash(:sha256, [key, signed])
    <<signed::binary, signature::binary>>
  end

  defp checksum(body, crc_extra), do: CRC.accumulate_byte(crc_extra, CRC.accumulate(body, 0xFFFF))

  # MAVLink 2 drops trailing zero bytes of the payload, keeping at least one.
  defp trim_zeros(payload, 1), do: binary_part(payload, 0, 1)

  defp trim_zeros(payload, n) do
    case payload do
      <<_::binary-size(n - 1), 0, _::binary>> -> trim_zeros(payload, n - 1)
      _ -> binary_part(payload, 0, n)
    end
  end
end
