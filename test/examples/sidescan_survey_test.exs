defmodule Dolphin.Examples.SidescanSurveyTest do
  # The report's Listing 1, examples/sidescan_survey.exs, as its header says
  # to run it: three ArduSub SITL submarines near Comporta, their side-scan
  # sonars from the example's fleet file. Each surveys its own part at 5 m
  # deep and surfaces at home; the script says "Done!". (The built-in
  # simulator flies copters only: this example runs on SITL.)
  use ExUnit.Case, async: false

  alias Dolphin.SITL

  @moduletag :sitl
  @moduletag :tmp_dir
  @moduletag timeout: 600_000

  @root Path.expand("../..", __DIR__)

  setup do
    on_exit(fn ->
      Dolphin.Test.GroundStation.forget_vehicles()
      Dolphin.Clock.set_speedup(1)
    end)
  end

  if SITL.available?(:sub) do
    test "three side-scan submarines picked in Comporta survey their parts at the same time, 5 m deep, and surface", %{tmp_dir: dir} do
      events = Path.join(dir, "run.jsonl")
      {:ok, out} = StringIO.open("")
      {:ok, err} = StringIO.open("")

      argv = [
        Path.join(@root, "examples/sidescan_survey.exs"),
        "--sitl", "sub:3",
        "--home", "38.43462,-8.86118",
        "--fleet", Path.join(@root, "examples/sidescan_fleet.json"),
        "--speedup", "10",
        "--no-tlog",
        "--events", events
      ]

      code = Mix.Tasks.Dolphin.Run.main(argv, out: out, err: err)
      {_, printed} = StringIO.contents(out)
      assert code == 0, printed <> elem(StringIO.contents(err), 1)
      assert printed =~ "picked [1, 2, 3] (3 vehicles, type :uuv, airframe :sub, payload [:sidescan], in #Area<"
      assert printed =~ "message: Done!"

      log = events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(&:jiffy.decode(&1, [:return_maps]))
      finished = for %{"event" => "task_finished", "kind" => "mission"} = e <- log, do: {e["name"], e["vehicle"], e["result"]}
      # One survey per vehicle, all done.
      assert Enum.sort(finished) == [{"survey1", 1, "done"}, {"survey2", 2, "done"}, {"survey3", 3, "done"}]
      # Each flew its passes: the survey's four waypoints and the surfacing reported.
      for v <- 1..3 do
        reached = for %{"event" => "mission_item_reached", "vehicle" => ^v, "seq" => s} <- log, uniq: true, do: s
        assert Enum.sort(reached) |> Enum.take(-2) == [4, 5], "vehicle #{v} reached #{inspect(reached)}"
      end
    end
  end
end
