defmodule Dolphin.Examples.BackendsTest do
  # The examples that fly, run as a user runs them on both kinds of vehicles —
  # `mix dolphin.run examples/NAME.exs --sim N` and `--sitl N` (ArduCopter's
  # own flight code) — with the same `--for`, and compared on a normalised
  # history: for each mission the script flew, in order, how each run of it
  # ended and which of its items were reached; and how the script ended.
  # ArduCopter takes longer than the simulator here and there (its EKF needs
  # ~40 s before arming), so a run bounded by `--for` may get further on one
  # than on the other: the histories are compared as far as both went, and
  # each example names how far that must at least be.
  #
  # Not here: the two relays (4 and 6 SITL instances do not keep pace on a
  # 2-core machine at a speed-up that fits the suite's time).
  use ExUnit.Case, async: false

  alias Dolphin.MAVLink.Ardupilotmega.GlobalPositionInt
  alias Dolphin.MAVLink.{JSON, Tlog}
  alias Dolphin.Test.GroundStation
  alias Mix.Tasks.Dolphin.Run

  @moduletag :sitl
  @moduletag :tmp_dir
  @moduletag timeout: 900_000

  @examples Path.expand("../../examples", __DIR__)

  setup do
    on_exit(&GroundStation.forget_vehicles/0)
  end

  # example, vehicles, --for (nil: it ends by itself), SITL's speed-up, and
  # the least each mission name must have been flown on both
  @cases [
    {"search_and_signal", 3, nil, 10, %{"Search east" => 1, "Search west" => 1, "Home" => 1}},
    {"two_vehicles", 2, "14m", 15, %{"Survey Area 1" => 1, "Survey Area 2" => 1, "Return to base" => 2}},
    {"single_vehicle", 1, "14m", 15, %{"Survey Area" => 1, "Return to base" => 1}},
    {"standby_patrols", 2, nil, 15, %{"Tower 1" => 2, "Tower 2" => 2, "Home" => 4}},
    {"photo_patrol", 1, nil, 15, %{"Field patrol" => 1, "Home" => 1}}
  ]

  for {name, count, for_time, sitl_speedup, least} <- @cases do
    @tag example: name
    test "#{name}.exs: the same history on ArduCopter SITL as on the simulator", %{tmp_dir: dir} do
      sim = run(dir, unquote(name), "--sim", unquote(count), 25, unquote(for_time))
      sitl = run(dir, unquote(name), "--sitl", unquote(count), unquote(sitl_speedup), unquote(for_time))
      assert sim.code == 0, sim.output
      assert sitl.code == 0, sitl.output <> pace_note(sitl)
      assert sim.result == sitl.result

      for {mission, at_least} <- unquote(Macro.escape(least)) do
        a = Map.get(sim.history, mission, [])
        b = Map.get(sitl.history, mission, [])
        common = min(length(a), length(b))
        assert common >= at_least, "#{mission}: flown #{length(a)} time(s) on the simulator, #{length(b)} on SITL#{pace_note(sitl)}"

        for {x, y} <- Enum.zip(Enum.take(a, common), Enum.take(b, common)) do
          assert x.result == y.result, "#{mission}: #{inspect(a)} on the simulator, #{inspect(b)} on SITL"
          # Which DO commands (camera, jump) ArduCopter reports reached depends
          # on the loop they end in (docs/ardupilot.md): the items compared are
          # those both report.
          both = MapSet.intersection(MapSet.new(x.reached), MapSet.new(y.reached))
          {x, y} = {%{x | reached: Enum.filter(x.reached, &(&1 in both))}, %{y | reached: Enum.filter(y.reached, &(&1 in both))}}
          # Items reached: the same for a mission that ended by itself; for one
          # stopped by a condition (a battery threshold) as far as both went.
          n = if x.result == "done", do: max(length(x.reached), length(y.reached)), else: min(length(x.reached), length(y.reached))
          assert Enum.take(x.reached, n) == Enum.take(y.reached, n), "#{mission}: #{inspect(a)} on the simulator, #{inspect(b)} on SITL"
        end
      end

      # A script that ends by itself leaves its vehicles alike (landed and
      # disarmed after their last landing mission, or holding).
      if unquote(for_time) == nil, do: assert(sitl.disarmed_at_end == sim.disarmed_at_end)
    end
  end

  defp run(dir, name, backend, count, speedup, for_time) do
    events = Path.join(dir, "#{name}#{backend}.jsonl")
    tlog = Path.join(dir, "#{name}#{backend}.tlog")
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    bound = if for_time, do: ["--for", for_time], else: []
    argv = [Path.join(@examples, "#{name}.exs"), backend, "#{count}", "--speedup", "#{speedup}", "--events", events, "--tlog", tlog, "--quiet"] ++ bound
    code = Run.main(argv, out: out, err: err)
    GroundStation.forget_vehicles()
    all = events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(fn line -> {:ok, e} = JSON.decode(line); e end)

    %{
      code: code,
      output: elem(StringIO.contents(out), 1) <> elem(StringIO.contents(err), 1),
      result: all |> Enum.filter(&(&1["event"] == "script_finished")) |> List.last() |> Map.get("result"),
      history: history(all, for_time != nil),
      disarmed_at_end: disarmed_at_end(all),
      speedup: speedup,
      tlog: tlog
    }
  end

  # For each mission name, in the order they finished: how each ended and the
  # items it reached. A run ended by --for stops what flies at that moment:
  # those last tasks are not part of the history.
  defp history(all, bounded?) do
    reached =
      for %{"event" => "task_progress", "task_id" => id, "progress" => %{"reached" => r}} <- all, r != nil, reduce: %{} do
        acc -> Map.update(acc, id, [r], fn seen -> if List.last(seen) == r, do: seen, else: seen ++ [r] end)
      end

    ending = all |> Enum.filter(&(&1["event"] == "script_finished")) |> List.last() |> Map.get("t_ms")

    all
    |> Enum.filter(&(&1["event"] == "task_finished" and &1["kind"] == "mission"))
    |> Enum.reject(&(bounded? and &1["result"] == "stopped" and &1["t_ms"] >= ending - 2_000))
    |> Enum.group_by(& &1["name"], &%{result: &1["result"], reached: Map.get(reached, &1["task_id"], [])})
  end

  # Which vehicles were disarmed when the script ended, by the order they were picked.
  defp disarmed_at_end(all) do
    picked = for %{"event" => "picked", "vehicles" => vs} <- all, v <- vs, uniq: true, do: v
    armed = Enum.reduce(all, %{}, fn
      %{"event" => "armed", "vehicle" => v}, acc -> Map.put(acc, v, true)
      %{"event" => "disarmed", "vehicle" => v}, acc -> Map.put(acc, v, false)
      _, acc -> acc
    end)

    Enum.map(picked, &(not Map.get(armed, &1, false)))
  end

  # How fast SITL really ran: its own clock (time_boot_ms) against the log's
  # wall-clock stamps, as a fraction of the speed-up asked for.
  defp pace_note(%{tlog: tlog, speedup: k}) do
    {frames, _} = Tlog.read(Tlog.reader(), File.read!(tlog))
    stamps = for {us, %{sysid: 1, message: %GlobalPositionInt{time_boot_ms: t}}} <- frames, do: {us, t}

    case stamps do
      [{us0, t0} | _] when length(stamps) > 10 ->
        {us1, t1} = List.last(stamps)
        "\nSITL ran at #{Float.round((t1 - t0) / ((us1 - us0) / 1000) / k, 2)} of the #{k}x asked for"

      _ ->
        ""
    end
  end
end
