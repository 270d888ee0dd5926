defmodule Dolphin.Examples.MixedFleetTest do
  # examples/mixed_fleet.exs as its header says to run it: a plane, a copter
  # and a boat picked by airframe, one composition of their three tasks. On
  # the built-in simulator, and on ArduPlane, ArduCopter and ArduRover SITL
  # with the same history.
  # Its own Dolphin.Instance (vehicles, links, clock): its simulator runs
  # beside other tests; `make test` runs its SITL test alone (--max-cases 1).
  use ExUnit.Case, async: true

  alias Dolphin.SITL
  alias Dolphin.Test.ExampleRun

  @moduletag :tmp_dir
  @moduletag timeout: 600_000

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  # Runs the example on `vehicles`; each mission's vehicle and result, in the
  # order they finished, and whether the boat left when the copter was at the last spot.
  defp fly(vehicles, speedup, dir) do
    run = ExampleRun.run(dir, "mixed_fleet", Enum.join(vehicles, "-"), vehicles ++ ["--home", "38.43462,-8.86118", "--speedup", "#{speedup}"], nil)
    assert run.code == 0, run.output
    log = run.events
    assert [%{"vehicles" => [1]}, %{"vehicles" => [2]}, %{"vehicles" => [3]}] = for(%{"event" => "picked"} = e <- log, do: e)
    assert [%{"text" => "the boat is at the last spot"}] = for(%{"event" => "message"} = e <- log, do: e)
    finished = for %{"event" => "task_finished", "kind" => "mission"} = e <- log, do: {e["name"], e["vehicle"], e["result"]}
    {started, _} = Enum.split_while(log, &(&1["event"] != "task_started" or &1["name"] != "To the last spot"))
    %{finished: finished, boat_waited_for_the_copter: Enum.any?(started, &(&1["event"] == "condition_met"))}
  end

  defp as_written!(run) do
    # The survey first; then the inspection and the boat side by side (the boat's short trip ends first).
    assert [{"Wide survey", 1, "done"} | rest] = run.finished
    assert Enum.sort(rest) == [{"Inspection", 2, "done"}, {"To the last spot", 3, "done"}]
    assert run.boat_waited_for_the_copter
  end

  test "on the simulator: the plane surveys, then the copter inspects the spots while the boat waits for it at the shore and goes to the last", %{tmp_dir: dir} do
    as_written!(fly(["--sim", "plane:1,copter:1,boat:1"], 25, dir))
  end

  if SITL.available?(:plane) and SITL.available?(:boat) do
    @tag :sitl
    test "on ArduPlane, ArduCopter and ArduRover SITL: the same history as on the simulator", %{tmp_dir: dir} do
      sim = ExampleRun.beside(fn -> fly(["--sim", "plane:1,copter:1,boat:1"], 10, dir) end)
      sitl = fly(["--sitl", "plane:1,copter:1,boat:1"], 10, dir)
      as_written!(sitl)
      sim = Task.await(sim, :infinity)
      assert Enum.sort(sim.finished) == Enum.sort(sitl.finished)
    end
  end
end
