defmodule Dolphin.Examples.FireWatchTest do
  # examples/fire_watch.exs as its header says to run it, on the built-in
  # simulator with the world file it names: the fire, which the script does
  # not know of, is found, looked at, and both surveys are flown to their end.
  # The simulator's tests each in a Dolphin.Instance of their own, beside
  # other tests. The SITL test in the application's instance, as it always
  # was (`make test` runs it alone in its lane, --max-cases 1); why its
  # report once refused its events is said at the test.
  use ExUnit.Case, async: true

  alias Dolphin.Test.ExampleRun

  @moduletag :tmp_dir
  @moduletag timeout: 600_000

  @world Path.expand("../../examples/worlds/serra_fire.json", __DIR__)

  setup tags do
    if tags[:sitl], do: ExampleRun.clean_up_after_test(), else: Dolphin.Test.Instance.start!()
    :ok
  end

  # The simulator's runs at 10x, not the 20x of the example's header: its
  # copters land with about a tenth of their packs to spare, and a loaded
  # host's delays (uploads, the look's start) cost twice as much clock time
  # at 20x: beside the SITL tests and two busy loops, one copter's pack
  # reached 30 % as it landed, 28 s of flight later than on a quiet machine.
  @sim_speedup "10"

  # The fire of the world file, and how far from it a look is a look at it.
  @fire Dolphin.Geo.location(40.4470, -7.3740)
  @near_m 80

  # This one at 5x: its sent copter lands with that tenth to spare after
  # its look (the survey done at 266 s of clock, the pack at 30 % some 13 s
  # later). At 10x a fresh clone beside the SITL lanes and two busy loops
  # took 23 s of clock (2.3 s of real time; 6 ms quiet) from the look's end
  # to the resumed survey's upload, 11 retransmissions on a clean link,
  # and its pack reached 30 % before the survey's end.
  test "on the simulator: the fire is found, circled and photographed; the survey it broke off goes on; both land", %{tmp_dir: dir} do
    run = ExampleRun.run(dir, "fire_watch", "-sim", ["--sim", "copter:2+smoke", "--world", @world, "--speedup", "5"], nil)
    found_and_looked_at!(run, "-sim", dir)
  end

  if Dolphin.SITL.available?(:copter) do
    @tag :sitl
    test "on ArduCopter SITL with the sensor sidecar on each autopilot's second port: found, looked at, surveys flown", %{tmp_dir: dir} do
      # At 5x, where ArduCopter keeps its pace beside the other lanes. At 10x,
      # with the whole suite at once, its pace swung between 6.2x and 10.6x
      # within seconds; the clock follows the slowest vehicle a second
      # behind (Dolphin.SITL.Pace), and the flight report, which lines the
      # events up with the log by one rate and one offset, found only 11 of
      # 26 anchors within its 3 s and refused them (the mismatch of earlier
      # runs, docs/testing.md): a report of a run whose pace swings is still
      # to be placed piece by piece.
      run = ExampleRun.run(dir, "fire_watch", "-sitl", ["--sitl", "copter:2+smoke", "--world", @world, "--speedup", "5"], nil)
      assert run.output =~ "sensor sidecar on 127.0.0.1:"
      found_and_looked_at!(run, "-sitl", dir)
    end
  end

  test "two fires, one in each half: each copter looks at its own while the other flies on, and both go back to their surveys", %{tmp_dir: dir} do
    # A wind from the north, across the line between the fires: each fire's
    # plume drifts south, away from the other's (along that line, one's smoke
    # reached within 150 m, the example's `apart`, of where the other's was
    # detected). Where along a plume a reading first passes the threshold
    # depends on a loaded host's timing, and a plume reaches farther than
    # `apart`: a fire may be detected twice, far apart.
    world = Path.expand("../fixtures/sensors/two_fires.json", __DIR__)

    # A fire seen twice along its plume costs a second look. With the
    # simulator's 3,300 mAh packs, a fresh clone's run beside the SITL lanes
    # saw the second copter's pack reach 30 % at 286 s, in that second look,
    # and the example's low-battery branch (the next test's subject) stopped
    # it. Packs twice as large (BATT_CAPACITY, set as each copter is
    # discovered, long before it takes off) keep this test to its own.
    Dolphin.Vehicles.subscribe(:all)
    task = Task.async(fn -> ExampleRun.run(dir, "fire_watch", "-two", ["--sim", "copter:2+smoke", "--world", world, "--speedup", @sim_speedup], nil) end)

    for _ <- 1..2 do
      receive do
        {:dolphin, :vehicles, {:vehicle_discovered, id}} -> assert {:ok, 6600.0} = Dolphin.Vehicles.set_param(id, "BATT_CAPACITY", 6600)
      # (A fresh VM's start, its simulator's and the discoveries: beside two
      # busy loops and the rest of the suite a minute was not enough.)
      after
        180_000 ->
          ended = with {:ok, run} <- Task.yield(task, 0), do: "; the run ended:\n#{run.output}", else: (_ -> "")
          flunk("the two copters were not discovered within three minutes#{ended}")
      end
    end

    run = Task.await(task, 600_000)
    assert run.code == 0, run.output
    assert run.result == "done"

    # Each fire detected, by the copter surveying its half, which was sent to look.
    detections = for %{"event" => "sensor_threshold"} = e <- run.events, do: e
    why = "the detections: #{inspect(detections)}\n#{run.output}"
    near = fn fire -> for d <- detections, Dolphin.Geo.distance(Dolphin.Geo.location(d["lat"], d["lon"]), fire) < 170, uniq: true, do: {d["vehicle"], d["sent"]} end
    assert [{v1, v1}] = near.(Dolphin.Geo.location(40.4470, -7.3740)), why
    assert [{v2, v2}] = near.(Dolphin.Geo.location(40.4460, -7.3766)), why
    assert Enum.sort([v1, v2]) == [1, 2], why

    # Every look done; each copter went back to its survey after each of its looks.
    looks = for %{"event" => "task_finished", "name" => "Look at the smoke"} = e <- run.events, do: {e["vehicle"], e["result"]}
    assert looks |> Enum.map(&elem(&1, 1)) |> Enum.uniq() == ["done"], why
    assert looks |> Enum.map(&elem(&1, 0)) |> Enum.uniq() |> Enum.sort() == [1, 2], why

    for v <- [1, 2] do
      surveys = Enum.count(run.events, &(&1["event"] == "task_started" and &1["vehicle"] == v and String.starts_with?(&1["name"] || "", "Survey")))
      assert surveys == 1 + Enum.count(looks, &(elem(&1, 0) == v)), why
    end

    assert run.disarmed_at_end
  end

  test "a battery runs low while a copter looks at the smoke: the look and the other's survey are stopped, both go home and land", %{tmp_dir: dir} do
    # The example's Listing 3 branch. Its pack cannot drain from 90 % to 30 %
    # in one survey: the other copter's pack is made to fail (25 %) the
    # moment the detection is announced, while the look is on its way.
    Dolphin.Events.subscribe()
    on_exit(fn -> Dolphin.Events.unsubscribe() end)
    task = Task.async(fn -> ExampleRun.run(dir, "fire_watch", "-low", ["--sim", "copter:2+smoke", "--world", @world, "--speedup", @sim_speedup], nil) end)
    %{sent: sent} = receive_event(&match?(%{event: :sensor_threshold, sent: s} when is_integer(s), &1))
    [other] = [1, 2] -- [sent]
    :ok = Dolphin.Sim.set_battery(other, 0.25)
    run = Task.await(task, 600_000)

    assert run.code == 0, run.output
    assert run.result == "done"
    assert run.output =~ "message: a battery is low: both go home"
    assert run.output =~ "message: fire watch over"

    missions = for %{"event" => "task_finished", "kind" => "mission"} = e <- run.events, do: {e["name"], e["vehicle"], e["result"]}
    why = "the missions: #{inspect(missions)}\n#{run.output}"
    # The look, never finished, and the other's survey stopped by the low battery; then each flew home.
    refute {"Look at the smoke", sent, "done"} in missions, why
    assert [{_, ^other, "stopped"}] = for({"Survey " <> _, ^other, _} = m <- missions, do: m), why
    assert {"Home", sent, "done"} in missions, why
    assert {"Home", other, "done"} in missions, why
    assert run.disarmed_at_end
  end

  defp receive_event(fun) do
    receive do
      {:dolphin, :events, e} -> if fun.(e), do: e, else: receive_event(fun)
    after
      300_000 -> flunk("no such event in 5 minutes")
    end
  end

  test "a fleet file gives a simulated vehicle its sensors: the pick finds the one that carries smoke", %{tmp_dir: dir} do
    script = Path.join(dir, "who_smells.exs")

    File.write!(script, """
    use Dolphin.Script
    sensor :smoke, from: {:named_value, "SMOKE"}
    v = pick(sensors: [:smoke], timeout: seconds(30))
    message("picked \#{inspect(Dolphin.Fleet.VehicleSet.ids(v))}")
    """)

    fleet = Path.join(dir, "fleet.json")
    File.write!(fleet, ~s({"vehicles": [{"id": 2, "sensors": ["smoke"]}]}))
    run = ExampleRun.run(dir, script, "", ["--sim", "2", "--fleet", fleet, "--world", @world, "--speedup", @sim_speedup], nil)
    assert run.code == 0, run.output
    assert run.output =~ "message: picked [2]"

    File.write!(fleet, ~s({"vehicles": [{"id": 2, "sensors": ["smoek"]}]}))
    {:ok, out} = StringIO.open("")
    assert Mix.Tasks.Dolphin.Run.main([script, "--sim", "2", "--fleet", fleet, "--no-tlog"], out: out, err: out) == 1
    assert elem(StringIO.contents(out), 1) =~ ~s[vehicle #1: no simulated sensor "smoek" (the simulator's sensors are range, smoke, water_temp)]
  end

  defp found_and_looked_at!(run, label, dir) do
    assert run.code == 0, run.output
    assert run.result == "done"

    # One detection, near the fire, and the vehicle that read it sent to look.
    assert [detection] = for(%{"event" => "sensor_threshold"} = e <- run.events, do: e)
    assert %{"sensor" => "smoke", "condition" => "smoke above 0.4", "sent" => sent, "vehicle" => sent} = detection
    assert detection["value"] > 0.4
    at = Dolphin.Geo.location(detection["lat"], detection["lon"])
    assert Dolphin.Geo.distance(at, @fire) < @near_m, "detected #{round(Dolphin.Geo.distance(at, @fire))} m from the fire"
    assert run.output =~ ~r/message: smoke 0\.\d+ read by vehicle #{sent} at 40\.44\d+, -7\.37\d+/

    missions = for %{"event" => "task_finished", "kind" => "mission"} = e <- run.events, do: {e["name"], e["vehicle"], e["result"]}
    # Its survey stopped to look, the look done, the rest of the survey flown to its landing.
    assert {"Look at the smoke", ^sent, "done"} = Enum.find(missions, &(elem(&1, 0) == "Look at the smoke"))
    surveys = for({"Survey " <> _, _, _} = m <- missions, do: m)
    [other] = [1, 2] -- [sent]
    assert match?([{_, ^sent, "stopped"}, {_, ^sent, "done"}], for({_, ^sent, _} = m <- surveys, do: m)), "the surveys: #{inspect(surveys)}\n#{run.output}"
    assert match?([{_, ^other, "done"}], for({_, ^other, _} = m <- surveys, do: m)), "the surveys: #{inspect(surveys)}\n#{run.output}"
    assert run.disarmed_at_end
    refute run.output =~ "a battery is low"

    # Looked at within two minutes of clock time of the detection (docs/missions.md says so).
    t = fn name -> Enum.find_value(run.events, &(&1["event"] == "task_finished" and &1["name"] == name && &1["t_ms"])) end
    detected_at = Enum.find_value(run.events, &(&1["event"] == "sensor_threshold" && &1["t_ms"]))
    assert t.("Look at the smoke") - detected_at < 120_000

    # Never closer than the least separation in the air (each lands on its own pad).
    {:ok, log} = Dolphin.Report.FlightLog.read_file(run.tlog)
    assert Dolphin.Report.Separation.closest(log).least.across > 20
    # The photographs of the look, as the simulator's camera reports them
    # (SITL's servo camera reports none: docs/ardupilot.md).
    if label == "-sim", do: assert(log.vehicles[sent].photos != [])

    # The report of the run plots the smoke read and marks the detection on the map.
    html = Path.join(dir, "report.html")
    assert {:ok, _} = Dolphin.Report.write(run.tlog, Path.join(dir, "fire_watch#{label}.jsonl"), html)
    page = File.read!(html)
    assert page =~ ~s(<svg class="plot sensor")
    assert page =~ "smoke"
    assert page =~ ~s(class="detection")
  end
end
