defmodule Dolphin.Examples.ScenariosTest do
  # The report's scenarios and the other examples, run as a user runs them —
  # `mix dolphin.run examples/NAME.exs --sim N --speedup 25 --events FILE` —
  # against the simulator over UDP on 127.0.0.1, judged from the event log.
  # At 25× a vehicle's 1 s mission re-request is 40 ms of real time and its
  # 20 s link timeout 0.8 s: on a shared, busy machine 50× made stalls of a
  # few hundred milliseconds read as lost vehicles and cancelled uploads.
  # Changes the clock's speed-up and runs simulated fleets: not async.
  use ExUnit.Case, async: false

  alias Dolphin.MAVLink.JSON
  alias Dolphin.Test.GroundStation
  alias Mix.Tasks.Dolphin.Run

  @moduletag :scenario
  @moduletag :tmp_dir
  @moduletag timeout: 600_000

  @examples Path.expand("../../examples", __DIR__)

  # Runs an example; returns the exit status, the output and the events.
  defp run_example(dir, name, sim, extra \\ []) do
    events = Path.join(dir, "#{name}.jsonl")
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    tlog = Path.join(dir, "#{name}.tlog")
    argv = [Path.join(@examples, "#{name}.exs"), "--sim", "#{sim}", "--speedup", "25", "--events", events, "--tlog", tlog, "--quiet"] ++ extra
    code = Run.main(argv, out: out, err: err)
    GroundStation.forget_vehicles()
    output = elem(StringIO.contents(out), 1) <> elem(StringIO.contents(err), 1)

    parsed =
      events
      |> File.read!()
      |> String.split("\n", trim: true)
      |> Enum.map(fn line -> {:ok, e} = JSON.decode(line); e end)

    {code, output, parsed}
  end

  # The simulated vehicles of one run are not those of the next (whose system
  # ids start at 1 again): the ground station forgets them.
  setup do
    on_exit(&GroundStation.forget_vehicles/0)
  end

  defp events(all, name), do: Enum.filter(all, &(&1["event"] == name))

  defp tasks(all, result, name),
    do: Enum.filter(all, &(&1["event"] == "task_finished" and &1["kind"] == "mission" and &1["result"] == result and &1["name"] == name))

  test "Listing 2: two full rounds; the survey stops within 1 s of the battery crossing 30 %, the vehicle lands at home", %{tmp_dir: dir} do
    {code, output, all} = run_example(dir, "single_vehicle", 1, ["--for", "28m"])
    assert code == 0, output

    stopped = tasks(all, "stopped", "Survey Area")
    returned = tasks(all, "done", "Return to base")
    assert length(stopped) >= 2 and length(returned) >= 2, output

    # Each stop follows the battery condition (until's condition_met) within 1 s of clock time.
    for stop <- Enum.take(stopped, 2) do
      met = all |> events("condition_met") |> Enum.filter(&(&1["condition"] =~ "< 0.3" and &1["t_ms"] <= stop["t_ms"])) |> List.last()
      assert met, "no condition_met before #{inspect(stop)}"
      assert stop["t_ms"] - met["t_ms"] <= 1_000
    end

    # Back home: landed and disarmed (the mission's completion), then recharged before the next round.
    disarms = events(all, "disarmed")
    assert length(disarms) >= 2
    [first_return | _] = returned
    next_start = all |> events("task_started") |> Enum.find(&(&1["name"] == "Survey Area" and &1["t_ms"] > first_return["t_ms"]))
    assert next_start
    # Recharging from near empty to 90 % at 0.5 %/s takes minutes.
    assert next_start["t_ms"] - first_return["t_ms"] > 60_000
  end

  test "Listing 3: the two surveys get different vehicles and both come back", %{tmp_dir: dir} do
    {code, output, all} = run_example(dir, "two_vehicles", 2, ["--for", "15m"])
    assert code == 0, output
    north = all |> events("task_started") |> Enum.find(&(&1["kind"] == "mission" and &1["name"] == "Survey Area 1"))
    south = all |> events("task_started") |> Enum.find(&(&1["kind"] == "mission" and &1["name"] == "Survey Area 2"))
    assert north["vehicle"] != south["vehicle"]
    assert Enum.sort(Enum.map(tasks(all, "done", "Return to base"), & &1["vehicle"])) |> Enum.take(2) |> Enum.sort() == Enum.sort([north["vehicle"], south["vehicle"]])
    assert [%{"items" => 42} | _] = events(all, "mission_uploaded") |> Enum.filter(&(&1["name"] == "Survey Area 1"))
  end

  test "the continuous relay keeps two vehicles airborne from the first hand-over on", %{tmp_dir: dir} do
    {code, output, all} = run_example(dir, "relay_continuous", 6)
    assert code == 0, output
    assert %{"result" => "done"} = all |> events("script_finished") |> List.last()

    # Who is armed, over time.
    {airborne, timeline} =
      all
      |> Enum.filter(&(&1["event"] in ["armed", "disarmed"]))
      |> Enum.map_reduce(MapSet.new(), fn e, set ->
        set = if e["event"] == "armed", do: MapSet.put(set, e["vehicle"]), else: MapSet.delete(set, e["vehicle"])
        {{e["t_ms"], MapSet.size(set)}, set}
      end)
      |> then(fn {timeline, set} -> {set, timeline} end)

    assert MapSet.size(airborne) == 0
    # The first hand-over: a third vehicle armed. The last shift: the last "Watch" mission stopped.
    {first_handover, _} = Enum.find(timeline, fn {_, n} -> n >= 3 end)
    last_watch = all |> Enum.filter(&(&1["event"] == "task_finished" and &1["kind"] == "mission" and &1["name"] =~ "Watch")) |> List.last()
    window = Enum.filter(timeline, fn {t, _} -> t >= first_handover and t < last_watch["t_ms"] end)
    assert window != []
    assert Enum.all?(window, fn {_, n} -> n >= 2 end), inspect(window)
  end

  test "Listing 4, faithful: pairs take turns", %{tmp_dir: dir} do
    {code, output, all} = run_example(dir, "relay", 4, ["--for", "20m"])
    assert code == 0, output
    flown = all |> events("task_started") |> Enum.filter(&(&1["kind"] == "mission" and &1["name"] =~ "Survey Area")) |> Enum.map(& &1["vehicle"])
    # The second pair is different from the first.
    assert length(flown) >= 4
    assert MapSet.disjoint?(MapSet.new(Enum.take(flown, 2)), MapSet.new(Enum.slice(flown, 2, 2)))
  end

  test "the other examples finish as designed", %{tmp_dir: dir} do
    {code, output, all} = run_example(dir, "standby_patrols", 2)
    assert code == 0, output
    assert length(events(all, "task_finished") |> Enum.filter(&(&1["name"] =~ "Tower" and &1["result"] == "stopped"))) == 4

    {code, output, all} = run_example(dir, "search_and_signal", 3)
    assert code == 0, output
    assert [%{"key" => "found"}] = events(all, "signal_posted")
    assert [%{"key" => "found"}] = events(all, "signal_consumed")
    assert [_] = all |> events("task_finished") |> Enum.filter(&(&1["name"] =~ "Look at" and &1["result"] == "stopped"))

    {code, output, all} = run_example(dir, "photo_patrol", 3)
    assert code == 0, output
    assert [%{"result" => "stopped"}] = tasks(all, "stopped", "Field patrol")
    assert [_] = tasks(all, "done", "Home")
    assert output =~ "patrol over"
  end
end
