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
end
