defmodule Dolphin.MAVLink.CRC do
  @moduledoc """
  The MAVLink checksum: CRC-16/MCRF4XX ("X.25" in MAVLink's sources; initial
  value `0xFFFF`, reflected polynomial `0x8408`, no final XOR), and CRC_EXTRA,
  the per-message seed byte computed from a message's definition.

      iex> Dolphin.MAVLink.CRC.x25("123456789")
      0x6F91

  `checksum/4` and `frame_checksum/5` run in C when the library built from
  `c_src/dolphin_crc.c` is loaded (see `implementation/0`). In Erlang, the hot
  path consumes two bytes per step through a 65,536-entry table built at
  compile time: the register is 16 bits wide, so XOR-ing two data bytes into it
  and shifting 16 times is one table look-up. Sixteen bytes are matched per
  call: the per-call cost of matching the rest of a binary is larger than the
  look-ups themselves.
  """

  import Bitwise

  @poly 0x8408

  step = fn crc -> if (crc &&& 1) == 1, do: bxor(crc >>> 1, @poly), else: crc >>> 1 end
  shift = fn value, times -> Enum.reduce(1..times, value, fn _, crc -> step.(crc) end) end

  @table8 0..255 |> Enum.map(&shift.(&1, 8)) |> List.to_tuple()
  @table16 0..65_535 |> Enum.map(&shift.(&1, 16)) |> List.to_tuple()

  @typedoc "A 16-bit CRC register."
  @type crc :: 0..0xFFFF

  @doc "CRC of `data` from the initial value `0xFFFF`."
  @spec x25(iodata()) :: crc()
  def x25(data), do: accumulate(IO.iodata_to_binary(data), 0xFFFF)

  @doc """
  The checksum of a frame: CRC from `0xFFFF` over `length` bytes of `binary`
  from `offset` (the bytes after the magic through the payload), then the
  message's CRC_EXTRA byte.
  """
  @spec checksum(binary(), non_neg_integer(), non_neg_integer(), byte()) :: crc()
  def checksum(binary, offset, length, crc_extra),
    do: accumulate_byte(crc_extra, accumulate(binary_part(binary, offset, length), 0xFFFF))

  @doc """
  Which implementation computes `checksum/4` and `frame_checksum/5`:
  `:native` (the C library built from `c_src/dolphin_crc.c` into `priv/`,
  several times faster) or `:erlang` (this module's code, used when the
  library was not built or cannot be loaded).
  """
  @spec implementation() :: :native | :erlang
  def implementation, do: :erlang

  # The C library replaces checksum/4, frame_checksum/5, frame_v2/4 and implementation/0
  # when it loads; if it does not, their Erlang definitions stay.
  @on_load :load_native
  defp load_native do
    with dir when is_list(dir) <- :code.priv_dir(:dolphin),
         {:error, {reason, text}} when reason != :reload <- :erlang.load_nif(:filename.join(dir, ~c"dolphin_crc"), 0) do
      if reason != :load_failed or File.exists?(Path.join(dir, "dolphin_crc.so")),
        do: :error_logger.warning_msg(~c"MAVLink checksum in Erlang: ~ts~n", [text])
    end

    :ok
  end

  @doc """
  The checksum of a MAVLink 2 frame from its first seven bytes as one
  little-endian integer (magic, len, flags, compat, seq, sysid, compid), its
  message id and the first `len` bytes of `payload`: what `checksum/4` gives
  over the frame's bytes, without needing them built (an encoder checksums
  before building the frame once).
  """
  @spec frame_checksum(non_neg_integer(), non_neg_integer(), binary(), non_neg_integer(), byte()) :: crc()
  def frame_checksum(header, msgid, payload, len, crc_extra), do: frame_checksum_erlang(header, msgid, payload, len, crc_extra)

  @doc false
  # frame_checksum/5 in Erlang, kept callable when the C library replaces it (for its tests).
  @spec frame_checksum_erlang(non_neg_integer(), non_neg_integer(), binary(), non_neg_integer(), byte()) :: crc()
  def frame_checksum_erlang(header, msgid, payload, len, crc_extra) do
    crc = elem(@table16, bxor(0xFFFF, header >>> 8 &&& 0xFFFF))
    crc = elem(@table16, bxor(crc, header >>> 24 &&& 0xFFFF))
    crc = elem(@table16, bxor(crc, header >>> 40 &&& 0xFFFF))
    crc = elem(@table16, bxor(crc, msgid &&& 0xFFFF))
    accumulate_byte(crc_extra, accumulate(binary_part(payload, 0, len), accumulate_byte(msgid >>> 16, crc)))
  end

  @doc """
  The MAVLink 2 frame of `payload`, the whole of its message (`max_len`
  bytes): its trailing zero bytes dropped (one kept at least), its length
  put into `header` (the frame's first seven bytes as one little-endian
  integer, its length byte 0), then `msgid`, the payload kept and the
  checksum. In C with the library: the frame is built in one call.
  """
  @spec frame_v2(non_neg_integer(), non_neg_integer(), binary(), byte()) :: binary()
  def frame_v2(header, msgid, payload, crc_extra), do: frame_v2_erlang(header, msgid, payload, crc_extra)

  @doc false
  # frame_v2/4 in Erlang, kept callable when the C library replaces it (for its tests).
  @spec frame_v2_erlang(non_neg_integer(), non_neg_integer(), binary(), byte()) :: binary()
  def frame_v2_erlang(header, msgid, payload, crc_extra) do
    len = trimmed_size(payload, byte_size(payload))
    header = header ||| len <<< 8
    crc = frame_checksum(header, msgid, payload, len, crc_extra)
    <<header::little-56, msgid::little-24, payload::binary-size(len), crc::little-16>>
  end

  # MAVLink 2 drops trailing zero bytes of the payload, keeping at least one.
  # Only the length is found here (the frame takes that many bytes of the
  # payload as it is built): four bytes per look, the last one first.
  defp trimmed_size(payload, n) when n >= 4 do
    <<_::binary-size(n - 4), tail::32, _::binary>> = payload

    cond do
      tail == 0 -> trimmed_size(payload, n - 4)
      (tail &&& 0xFF) != 0 -> n
      (tail &&& 0xFFFF) != 0 -> n - 1
      (tail &&& 0xFFFFFF) != 0 -> n - 2
      true -> n - 3
    end
  end

  defp trimmed_size(_payload, n) when n <= 1, do: 1

  defp trimmed_size(payload, n) do
    case payload do
      <<_::binary-size(n - 1), 0, _::binary>> -> trimmed_size(payload, n - 1)
      _ -> n
    end
  end

  @doc "Continues a CRC over `data`."
  @spec accumulate(binary(), crc()) :: crc()
  def accumulate(
        <<w1::little-16, w2::little-16, w3::little-16, w4::little-16, w5::little-16, w6::little-16, w7::little-16, w8::little-16, rest::binary>>,
        crc
      ) do
    crc = elem(@table16, bxor(crc, w1))
    crc = elem(@table16, bxor(crc, w2))
    crc = elem(@table16, bxor(crc, w3))
    crc = elem(@table16, bxor(crc, w4))
    crc = elem(@table16, bxor(crc, w5))
    crc = elem(@table16, bxor(crc, w6))
    crc = elem(@table16, bxor(crc, w7))
    accumulate(rest, elem(@table16, bxor(crc, w8)))
  end

  def accumulate(<<w1::little-16, w2::little-16, rest::binary>>, crc),
    do: accumulate(rest, elem(@table16, bxor(elem(@table16, bxor(crc, w1)), w2)))

  def accumulate(<<word::little-16, rest::binary>>, crc), do: accumulate(rest, elem(@table16, bxor(crc, word)))

  def accumulate(<<byte>>, crc), do: accumulate_byte(byte, crc)
  def accumulate(<<>>, crc), do: crc

  @doc "Continues a CRC over one byte (how CRC_EXTRA closes a frame's checksum)."
  @spec accumulate_byte(byte(), crc()) :: crc()
  def accumulate_byte(byte, crc), do: bxor(crc >>> 8, elem(@table8, band(bxor(crc, byte), 0xFF)))

  @doc """
  CRC_EXTRA of a message, from its name and its non-extension fields in wire
  order, each given as `{c_type, name, array_length | nil}` (`c_type` without the
  array suffix, e.g. `"uint8_t"`, `"char"`), exactly as mavgen seeds it.

      iex> Dolphin.MAVLink.CRC.crc_extra("HEARTBEAT", [
      ...>   {"uint32_t", "custom_mode", nil}, {"uint8_t", "type", nil},
      ...>   {"uint8_t", "autopilot", nil}, {"uint8_t", "base_mode", nil},
      ...>   {"uint8_t", "system_status", nil}, {"uint8_t", "mavlink_version", nil}])
      50
  """
  @spec crc_extra(String.t(), [{String.t(), String.t(), pos_integer() | nil}]) :: byte()
  def crc_extra(name, wire_fields) do
    crc =
      Enum.reduce(wire_fields, accumulate(name <> " ", 0xFFFF), fn {type, field, array_length}, crc ->
        crc = accumulate(type <> " " <> field <> " ", crc)
        if array_length, do: accumulate_byte(array_length, crc), else: crc
      end)

    bxor(crc &&& 0xFF, crc >>> 8)
  end
end
