defmodule Dolphin.Events.WriterTest do
  use ExUnit.Case, async: true

  alias Dolphin.Events.Writer

  @moduletag :tmp_dir

  test "every event it was sent is written, in order, one JSON line each, even those still queued when it is stopped", %{tmp_dir: dir} do
    path = Path.join(dir, "events.jsonl")
    {:ok, writer} = Writer.start_link(path: path, origin_ms: 1_000)
    # A burst larger than a batch, all queued before the writer sees the first.
    :sys.suspend(writer)
    for i <- 1..2_345, do: send(writer, {:dolphin, :events, %{event: :armed, vehicle: i, at_ms: 1_000 + i}})
    :sys.resume(writer)
    assert :ok = Writer.stop(writer)

    lines = path |> File.read!() |> String.split("\n", trim: true)
    assert length(lines) == 2_345
    assert Enum.map(lines, &:jiffy.decode(&1, [:return_maps])["vehicle"]) == Enum.to_list(1..2_345)
    assert hd(lines) == ~s({"t_ms":1,"event":"armed","vehicle":1})
  end

  test "a file it cannot write is said at its start", %{tmp_dir: dir} do
    Process.flag(:trap_exit, true)
    assert {:error, "cannot write " <> why} = Writer.start_link(path: Path.join([dir, "no such dir", "events.jsonl"]))
    assert why =~ "no such file or directory"
  end

  test "a file that cannot be written (a full disk) is said once, and the writer goes on to its stop" do
    log =
      ExUnit.CaptureLog.capture_log(fn ->
        {:ok, writer} = Writer.start_link(path: "/dev/full", origin_ms: 0)
        for i <- 1..3_000, do: send(writer, {:dolphin, :events, %{event: :armed, vehicle: i, at_ms: i}})
        assert :ok = Writer.stop(writer)
      end)

    assert [_once] = Regex.scan(~r/--events \/dev\/full: cannot write \(no space left on device\): the run's events from now on are not in it/, log)
  end
end
