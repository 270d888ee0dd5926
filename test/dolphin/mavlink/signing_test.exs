defmodule Dolphin.MAVLink.SigningTest do
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.{Frame, Parser, Signing}
  alias Dolphin.MAVLink.Ardupilotmega.{Heartbeat, RadioStatus}

  doctest Dolphin.MAVLink.Signing

  @key :binary.copy(<<0x5A>>, 32)
  @dialect Dolphin.MAVLink.Ardupilotmega

  defp signed(signer, msg, opts) do
    {bytes, signer} = Signing.encode(signer, msg, opts)
    {:ok, frame, <<>>} = Frame.decode(bytes, @dialect)
    {frame, signer}
  end

  test "timestamps of a signer strictly increase, even when the clock stands still" do
    signer = Signing.new(key: @key, link_id: 4, timestamp: 0)
    {a, signer} = signed(signer, %Heartbeat{}, now: 500)
    {b, signer} = signed(signer, %Heartbeat{}, now: 500)
    {c, _} = signed(signer, %Heartbeat{}, now: 10_000)
    assert [a.signature.timestamp, b.signature.timestamp, c.signature.timestamp] == [500, 501, 10_000]
    assert a.signature.link_id == 4 and a.incompat_flags == 1
  end

  test "the clock is 10 µs units since 2015-01-01" do
    now = Signing.now()
    expected = div(System.os_time(:microsecond) - 1_420_070_400_000_000, 10)
    assert abs(now - expected) < 100_000
  end

  test "replay protection is per (sysid, compid, link id) stream" do
    signer = Signing.new(key: @key, link_id: 1, timestamp: 0)
    {f1, signer} = signed(signer, %Heartbeat{}, sysid: 1, now: 10_000_000)
    {f2, _} = signed(signer, %Heartbeat{}, sysid: 1, now: 20_000_000)
    {other, _} = signed(Signing.new(key: @key, link_id: 1, timestamp: 0), %Heartbeat{}, sysid: 2, now: 15_000_000)

    checker = Signing.new(key: @key, timestamp: 0)
    {:ok, checker} = Signing.verify(checker, f2)
    # The same stream going back in time is a replay...
    assert {:error, :old_timestamp, _} = Signing.verify(checker, f1)
    assert {:error, :old_timestamp, _} = Signing.verify(checker, f2)
    # ...another stream less than a minute behind is fine.
    assert {:ok, checker} = Signing.verify(checker, other)
    # A new stream more than a minute (6,000,000 units) behind the local timestamp is not.
    {stale, _} = signed(Signing.new(key: @key, link_id: 9, timestamp: 0), %Heartbeat{}, sysid: 3, now: 1)
    assert {:error, :old_timestamp, _} = Signing.verify(checker, stale)
  end

  test "a fresh signing state starts its replay window at the clock: old captured traffic is refused" do
    {old, _} = signed(Signing.new(key: @key, timestamp: 0), %Heartbeat{}, now: 1_000)
    assert {:error, :old_timestamp, _} = Signing.verify(Signing.new(key: @key), old)
    {fresh, _} = signed(Signing.new(key: @key), %Heartbeat{}, [])
    assert {:ok, _} = Signing.verify(Signing.new(key: @key), fresh)
  end

  test "a changed byte or another key breaks the signature" do
    {frame, _} = signed(Signing.new(key: @key, timestamp: 0), %Heartbeat{type: 1}, now: 42)
    assert {:error, :bad_signature, _} = Signing.verify(Signing.new(key: :binary.copy(<<1>>, 32)), frame)

    <<head::binary-size(byte_size(frame.raw) - 1), last>> = frame.raw
    {:ok, tampered, <<>>} = Frame.decode(<<head::binary, Bitwise.bxor(last, 1)>>, @dialect)
    assert {:error, :bad_signature, _} = Signing.verify(Signing.new(key: @key), tampered)
  end

  test "unsigned frames follow the policy" do
    {:ok, plain, <<>>} = Frame.decode(Frame.encode(%Heartbeat{}), @dialect)
    {:ok, radio, <<>>} = Frame.decode(Frame.encode(%RadioStatus{rssi: 200}), @dialect)

    # Rejected by default, as the spec wants of a system with signing on.
    assert {:error, :unsigned, _} = Signing.verify(Signing.new(key: @key), plain)
    assert {:ok, _} = Signing.verify(Signing.new(key: @key, unsigned: :accept), plain)
    radio_ok = Signing.new(key: @key, unsigned: &match?(%RadioStatus{}, &1.message))
    assert {:ok, _} = Signing.verify(radio_ok, radio)
    assert {:error, :unsigned, _} = Signing.verify(radio_ok, plain)
  end

  test "keys are 32 bytes or 64 hex digits; bad options are caller mistakes" do
    assert Signing.new(key: String.duplicate("5a", 32)).key == @key
    assert_raise ArgumentError, ~r/32 bytes or 64 hex digits/, fn -> Signing.new(key: "short") end
    assert_raise ArgumentError, ~r/not hexadecimal/, fn -> Signing.new(key: String.duplicate("zz", 32)) end
    assert_raise ArgumentError, ~r/unsigned-frame policy/, fn -> Signing.new(key: @key, unsigned: :maybe) end
    assert_raise ArgumentError, ~r/MAVLink 1 frames cannot be signed/, fn ->
      Frame.encode(%Heartbeat{}, version: 1, signing: %{key: @key, link_id: 0, timestamp: 1})
    end
  end

  test "a parser with signing drops and counts bad, replayed and refused frames, keeping the rest" do
    signer = Signing.new(key: @key, link_id: 2, timestamp: 0)
    {good1, signer} = Signing.encode(signer, %Heartbeat{type: 1}, now: 100)
    {good2, _} = Signing.encode(signer, %Heartbeat{type: 2}, now: 200)
    {foreign, _} = Signing.encode(Signing.new(key: :binary.copy(<<7>>, 32), timestamp: 0), %Heartbeat{type: 3}, now: 300)
    plain = Frame.encode(%Heartbeat{type: 4})

    parser = Parser.new(signing: Signing.new(key: @key, timestamp: 0))
    {frames, parser} = Parser.feed(parser, good1 <> foreign <> good2 <> good1 <> plain)
    assert Enum.map(frames, & &1.message.type) == [1, 2]
    stats = Parser.stats(parser)
    assert {stats.frames, stats.bad_signature, stats.old_timestamp, stats.unsigned} == {2, 1, 1, 1}
    assert stats.bytes_skipped == byte_size(foreign) + byte_size(good1) + byte_size(plain)
  end
end
