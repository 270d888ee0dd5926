defmodule Dolphin.MAVLink.CRCTest do
  # The checksum's C implementation (c_src/dolphin_crc.c) against the Erlang
  # one it replaces, which stays the reference: CRC.accumulate/2 and
  # accumulate_byte/2 are never replaced.
  use ExUnit.Case, async: true

  import Bitwise
  import Dolphin.Property

  alias :proper_types, as: T
  alias Dolphin.MAVLink.CRC

  test "the C checksum is built and loaded (scripts/bootstrap installs the compiler)" do
    assert CRC.implementation() == :native
  end

  test "checksum/4 agrees with the Erlang reference on any bytes, offset and length" do
    check(
      forall({T.binary(), T.non_neg_integer(), T.non_neg_integer(), T.range(0, 255)}, fn {bytes, a, b, extra} ->
        offset = if bytes == "", do: 0, else: rem(a, byte_size(bytes) + 1)
        length = rem(b, byte_size(bytes) - offset + 1)
        reference = CRC.accumulate_byte(extra, CRC.accumulate(binary_part(bytes, offset, length), 0xFFFF))
        assert CRC.checksum(bytes, offset, length, extra) == reference
        true
      end),
      numtests: 2000
    )
  end

  test "frame_checksum/5 is the checksum of the MAVLink 2 frame it describes" do
    check(
      forall({T.vector(6, T.range(0, 255)), T.range(0, 0xFFFFFF), T.binary(), T.non_neg_integer(), T.range(0, 255)}, fn
        {[len, flags, compat, seq, sysid, compid], msgid, payload, n, extra} ->
          n = rem(n, byte_size(payload) + 1)
          header = 0xFD ||| len <<< 8 ||| flags <<< 16 ||| compat <<< 24 ||| seq <<< 32 ||| sysid <<< 40 ||| compid <<< 48
          bytes = <<len, flags, compat, seq, sysid, compid, msgid::little-24, binary_part(payload, 0, n)::binary>>
          reference = CRC.accumulate_byte(extra, CRC.accumulate(bytes, 0xFFFF))
          assert CRC.frame_checksum(header, msgid, payload, n, extra) == reference
          assert CRC.frame_checksum_erlang(header, msgid, payload, n, extra) == reference
          true
      end),
      numtests: 2000
    )
  end

  test "frame_v2/4 builds the MAVLink 2 frame of a payload: trailing zeros dropped, length, checksum, as the Erlang reference" do
    check(
      forall({T.vector(5, T.range(0, 255)), T.range(0, 0xFFFFFF), T.non_empty(T.binary()), T.non_neg_integer(), T.range(0, 255)}, fn
        {[flags, compat, seq, sysid, compid], msgid, bytes, zeros, extra} ->
          # Payloads ending in zeros (most do: fields left 0), up to 255 bytes in all.
          payload = binary_part(bytes <> :binary.copy(<<0>>, rem(zeros, 40)), 0, min(byte_size(bytes) + rem(zeros, 40), 255))
          header = 0xFD ||| flags <<< 16 ||| compat <<< 24 ||| seq <<< 32 ||| sysid <<< 40 ||| compid <<< 48
          kept = max(byte_size(String.trim_trailing(payload, <<0>>)), 1)
          body = <<kept, flags, compat, seq, sysid, compid, msgid::little-24, binary_part(payload, 0, kept)::binary>>
          crc = CRC.accumulate_byte(extra, CRC.accumulate(body, 0xFFFF))
          reference = <<0xFD, body::binary, crc::little-16>>
          assert CRC.frame_v2(header, msgid, payload, extra) == reference
          assert CRC.frame_v2_erlang(header, msgid, payload, extra) == reference
          true
      end),
      numtests: 2000
    )
  end

  test "reads of bytes outside the binary, and bad values, raise instead of reading memory" do
    assert_raise ArgumentError, fn -> CRC.frame_v2(0xFD ||| 5 <<< 8, 0, "ab", 0) end
    assert_raise ArgumentError, fn -> CRC.frame_v2(0xFD, 0x1000000, "ab", 0) end
    assert_raise ArgumentError, fn -> CRC.frame_v2(0xFD, 0, "", 0) end
    assert_raise ArgumentError, fn -> CRC.frame_v2(0xFD, 0, :binary.copy("a", 256), 0) end
    assert_raise ArgumentError, fn -> CRC.frame_v2(0xFD, 0, "ab", 256) end
    assert_raise ArgumentError, fn -> CRC.checksum("abc", 2, 2, 0) end
    assert_raise ArgumentError, fn -> CRC.checksum("abc", 4, 0, 0) end
    assert_raise ArgumentError, fn -> CRC.checksum("abc", -1, 1, 0) end
    assert_raise ArgumentError, fn -> CRC.checksum("abc", 0, 3, 256) end
    assert_raise ArgumentError, fn -> CRC.checksum(:abc, 0, 0, 0) end
    assert_raise ArgumentError, fn -> CRC.frame_checksum(0xFD, 0, "ab", 3, 0) end
    assert_raise ArgumentError, fn -> CRC.frame_checksum(0xFD, 0x1000000, "ab", 1, 0) end
    assert_raise ArgumentError, fn -> CRC.frame_checksum(-1, 0, "ab", 1, 0) end
  end

  test "a sub-binary is read from its own offset" do
    <<_, part::binary-size(9), _::binary>> = "x123456789yz"
    assert CRC.checksum(part, 0, 9, 0) == CRC.accumulate_byte(0, CRC.x25("123456789"))
  end
end
