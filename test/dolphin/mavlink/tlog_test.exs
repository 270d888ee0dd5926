defmodule Dolphin.MAVLink.TlogTest do
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.{Frame, Signing, Tlog}
  alias Dolphin.MAVLink.Ardupilotmega.{Attitude, Heartbeat, Statustext}

  doctest Dolphin.MAVLink.Tlog

  defp log(records), do: IO.iodata_to_binary(for {t, frame} <- records, do: Tlog.record(t, frame))

  test "records come back with their timestamps, whatever the chunking" do
    records = for i <- 1..50, do: {1_700_000_000_000_000 + i * 1000, Frame.encode(%Attitude{time_boot_ms: i, roll: i / 10}, seq: i)}
    bytes = log(records)

    for size <- [1, 7, 64, byte_size(bytes)] do
      {got, reader} =
        for(<<chunk::binary-size(size) <- bytes>>, do: chunk)
        |> Kernel.++([binary_part(bytes, div(byte_size(bytes), size) * size, rem(byte_size(bytes), size))])
        |> Enum.reduce({[], Tlog.reader()}, fn chunk, {acc, r} ->
          {recs, r} = Tlog.read(r, chunk)
          {acc ++ recs, r}
        end)

      assert {[], reader} = Tlog.finish(reader)
      assert Enum.map(got, fn {t, f} -> {t, f.raw} end) == records
      assert Tlog.stats(reader).frames == 50
    end
  end

  test "a corrupt record is skipped and counted; the records after it survive" do
    a = Frame.encode(%Heartbeat{type: 1})
    b = Frame.encode(%Heartbeat{type: 2})
    <<head::binary-size(11), byte, tail::binary>> = b
    bad = <<head::binary, Bitwise.bxor(byte, 0x40), tail::binary>>
    bytes = log([{1, a}, {2, bad}, {3, a}]) <> <<0, 0, 0>>

    {got, reader} = Tlog.read(Tlog.reader(), bytes)
    assert Enum.map(got, &elem(&1, 0)) == [1, 3]
    assert {[], reader} = Tlog.finish(reader)
    stats = Tlog.stats(reader)
    assert stats.frames == 2 and stats.bad_crc >= 1 and stats.truncated == 1

    # A log that ends inside a record (its frame claims more bytes than are
    # left) whose bytes hide a whole record: that one is kept.
    long = Frame.encode(%Statustext{text: String.duplicate("x", 50)})
    cut = binary_part(IO.iodata_to_binary(Tlog.record(5, long)), 0, 14)
    {[], reader} = Tlog.read(Tlog.reader(), cut <> IO.iodata_to_binary(Tlog.record(6, a)))
    assert {[{6, %Frame{raw: ^a}}], reader} = Tlog.finish(reader)
    assert Tlog.stats(reader).truncated == 1
  end

  test "by default unknown ids are dropped; a signed frame cut in its signature does not swallow the next record" do
    known = Frame.encode(%Heartbeat{type: 1})
    unknown = <<0xFD, 2, 0, 0, 0, 1, 1, 0x00, 0xFF, 0x7F, 0xAA, 0xBB, 0x12, 0x34>>
    {got, reader} = Tlog.read(Tlog.reader(), log([{1, known}, {2, unknown}, {3, known}]))
    {last, reader} = Tlog.finish(reader)
    assert Enum.map(got ++ last, &elem(&1, 0)) == [1, 3]
    assert Tlog.stats(reader).unknown_id >= 1

    key = :binary.copy(<<9>>, 32)
    {signed, _} = Signing.encode(Signing.new(key: key, timestamp: 0), %Heartbeat{type: 5}, now: 100)
    cut = binary_part(signed, 0, byte_size(signed) - 7)
    bytes = log([{1, cut}, {2, known}, {3, known}])

    for signing <- [nil, Signing.new(key: key, timestamp: 0, unsigned: :accept)] do
      {got, reader} = Tlog.read(Tlog.reader(signing: signing), bytes)
      {last, _} = Tlog.finish(reader)
      assert Enum.map(got ++ last, &elem(&1, 0)) == [2, 3], "signing: #{inspect(signing != nil)}"
    end
  end

  test "frames with an id the dialect does not know are kept when forwarding, counted apart" do
    known = Frame.encode(%Heartbeat{type: 1})
    # A well-formed MAVLink 2 frame of message id 0x7FFF00, which no dialect defines.
    unknown = <<0xFD, 2, 0, 0, 0, 1, 1, 0x00, 0xFF, 0x7F, 0xAA, 0xBB, 0x12, 0x34>>
    bytes = log([{1, known}, {2, unknown}, {3, known}, {4, unknown}])

    for split <- 0..byte_size(bytes) do
      <<a::binary-size(split), b::binary>> = bytes
      {r1, reader} = Tlog.read(Tlog.reader(unknown: :forward), a)
      {r2, reader} = Tlog.read(reader, b)
      {r3, reader} = Tlog.finish(reader)
      got = r1 ++ r2 ++ r3
      assert Enum.map(got, fn {t, f} -> {t, f.message && f.message.type} end) == [{1, 1}, {2, nil}, {3, 1}, {4, nil}], "split at #{split}"
      stats = Tlog.stats(reader)
      assert {stats.frames, stats.unknown_id, stats.bytes_skipped} == {2, 2, 0}
    end
  end

  @tag :interop
  @tag :tmp_dir
  test "pymavlink's mavutil reads our .tlog", %{tmp_dir: dir} do
    path = Path.join(dir, "flight.tlog")
    t0 = 1_700_000_000_000_000
    File.write!(path, log(for i <- 0..9, do: {t0 + i * 250_000, Frame.encode(%Attitude{time_boot_ms: i * 250, yaw: 0.5}, sysid: 1, seq: i)}))

    read = Dolphin.Test.Pymavlink.read_tlog(path)
    assert length(read) == 10

    for {{sysid, type, ts, fields}, i} <- Enum.with_index(read) do
      assert {sysid, type, fields["time_boot_ms"]} == {1, "ATTITUDE", i * 250}
      assert_in_delta ts, (t0 + i * 250_000) / 1_000_000, 1.0e-5
    end
  end
end
