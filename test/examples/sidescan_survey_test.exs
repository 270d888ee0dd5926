defmodule Dolphin.Examples.SidescanSurveyTest do
  # The report's Listing 1, examples/sidescan_survey.exs, as its header says
  # to run it: three submarines near Comporta, their side-scan sonars from
  # the example's fleet file. Each surveys its own part at 5 m deep and
  # surfaces at home; the script says "Done!". On the built-in simulator's
  # submarines, and on ArduSub SITL with the same history.
  # Its own Dolphin.Instance (vehicles, links, clock): its simulator runs
  # beside other tests; `make test` runs its SITL test alone (--max-cases 1).
  use ExUnit.Case, async: true

  alias Dolphin.SITL
  alias Dolphin.Test.ExampleRun

  @moduletag :tmp_dir
  @moduletag timeout: 600_000

  @root Path.expand("../..", __DIR__)

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  # Runs the example with `vehicles` (`--sim sub:3` or `--sitl sub:3`); its
  # history: each mission's vehicle and result, and the items each vehicle
  # reported reached.
  defp fly(vehicles, dir) do
    args = vehicles ++ ["--home", "38.43462,-8.86118", "--fleet", Path.join(@root, "examples/sidescan_fleet.json"), "--speedup", "10"]
    run = ExampleRun.run(dir, "sidescan_survey", Enum.join(vehicles, "-"), args, nil)
    assert run.code == 0, run.output
    log = run.events
    assert [%{"requirement" => picked, "vehicles" => [1, 2, 3]}] = for(%{"event" => "picked"} = e <- log, do: e)
    assert picked =~ "3 vehicles, type :uuv, airframe :sub, payload [:sidescan], in #Area<"
    assert [%{"text" => "Done!"}] = for(%{"event" => "message"} = e <- log, do: e)
    finished = for %{"event" => "task_finished", "kind" => "mission"} = e <- log, do: {e["name"], e["vehicle"], e["result"]}
    reached = for v <- 1..3, into: %{}, do: {v, for(%{"event" => "mission_item_reached", "vehicle" => ^v, "seq" => s} <- log, uniq: true, do: s) |> Enum.sort()}
    {Enum.sort(finished), reached}
  end

  defp surveyed!({finished, reached}) do
    # One survey per vehicle, all done.
    assert finished == [{"survey1", 1, "done"}, {"survey2", 2, "done"}, {"survey3", 3, "done"}]
    # Each flew its passes: the survey's four waypoints, then its surfacing at home.
    for v <- 1..3, do: assert(reached[v] == [1, 2, 3, 4, 5], "vehicle #{v} reached #{inspect(reached[v])}")
  end

  test "on the simulator: three side-scan submarines picked in Comporta survey their parts at the same time, 5 m deep, and surface", %{tmp_dir: dir} do
    surveyed!(fly(["--sim", "sub:3"], dir))
  end

  if SITL.available?(:sub) do
    @tag :sitl
    test "on ArduSub SITL: the same history as on the simulator", %{tmp_dir: dir} do
      sim = ExampleRun.beside(fn -> fly(["--sim", "sub:3"], dir) end)
      sitl = fly(["--sitl", "sub:3"], dir)
      surveyed!(sitl)
      assert Task.await(sim, :infinity) == sitl
    end
  end
end
