defmodule Mix.Tasks.Dolphin.RunTest do
  # In a Dolphin.Instance of the test's own (fleet source, vehicles, clock): async.
  use ExUnit.Case, async: true

  alias Mix.Tasks.Dolphin.Run

  doctest Mix.Tasks.Dolphin.Run

  @moduletag :tmp_dir

  # A run's vehicles are discovered afresh: none left known by a test before.
  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  defp script(dir, name, source) do
    path = Path.join(dir, name)
    File.write!(path, source)
    path
  end

  defp main(argv) do
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    code = Run.main(argv, out: out, err: err)
    {code, elem(StringIO.contents(out), 1), elem(StringIO.contents(err), 1)}
  end

  describe "bad usage is exit status 2" do
    test "no script, an unknown option, a bad duration, --sim with --fake, a missing file", %{tmp_dir: dir} do
      ok = script(dir, "ok.exs", "use Dolphin.Script\n")
      assert {2, _, err} = main([])
      assert err =~ "no script given"
      assert err =~ "usage: mix dolphin.run SCRIPT"
      assert {2, _, err} = main([ok, "--bogus"])
      assert err =~ "bad option --bogus"
      assert {2, _, err} = main([ok, "--for", "soon"])
      assert err =~ "--for soon: a duration more than 0 such as 90s"
      assert {2, _, err} = main([ok, "--sim", "1", "--fake", "1"])
      assert err =~ "do not go together"
      assert {2, _, err} = main([Path.join(dir, "nope.exs")])
      assert err =~ "no such script"
      assert {2, _, _} = main([ok, "--speedup", "0"])
      assert {2, _, err} = main([ok, "--connect", "carrier-pigeon:1"])
      assert err =~ "--connect carrier-pigeon:1"
      assert {2, _, err} = main([ok, "--sitl", "blimp:1,boat:2"])
      assert err =~ "--sitl blimp:1,boat:2: a number of copters, or airframes and counts such as boat:1,sub:3 (airframes: copter, plane, rover, boat, sub; 254 vehicles at most)"
      assert {2, _, _} = main([ok, "--sitl", "boat:0"])
      assert {2, _, err} = main([ok, "--sim", "quadplane:1"])
      assert err =~ "--sim quadplane:1: a number of copters, or airframes and counts such as boat:1,sub:3 (airframes: copter, plane, rover, boat, sub; 16256 vehicles at most)"
    end
  end

  describe "scripts" do
    test "a syntax error or an unknown word: file and line, status 1, nothing run", %{tmp_dir: dir} do
      Dolphin.Events.subscribe()
      bad = script(dir, "bad.exs", "use Dolphin.Script\nmessage(\"hi\")\nexecute %{v1 => \n")
      assert {1, "", err} = main([bad, "--fake", "1"])
      assert err =~ ~r/bad.exs:\d+:\d+: syntax error/

      typo = script(dir, "typo.exs", "use Dolphin.Script\nmessage(\"hi\")\nv = pik(type: :uav)\n_ = v\n")
      assert {1, "", err} = main([typo, "--fake", "1"])
      assert err =~ "typo.exs:3: undefined function pik/1"
      refute_received {:dolphin, :events, %{event: :message}}
      refute_received {:dolphin, :events, %{event: :vehicle_discovered}}
      refute_received {:dolphin, :events, %{event: :script_started}}
    end

    test "a script that completes: status 0, live output, and the events file", %{tmp_dir: dir} do
      path =
        script(dir, "survey.exs", """
        use Dolphin.Script
        alias Dolphin.Engine.FakePlatform

        v = pick(type: :uav, timeout: seconds(5))
        execute %{v => wait_for(battery(v) >= 0.9, then: during(seconds(2), FakePlatform.task("survey", duration: :infinity)))}
        release(v)
        message("Done!")
        """)

      events = Path.join(dir, "events.jsonl")
      assert {0, out, ""} = main([path, "--fake", "2", "--speedup", "20", "--events", events])
      assert out =~ "2 fake vehicle(s)"
      assert out =~ "message: Done!"
      assert out =~ ~s(test "survey" started on vehicle)
      assert out =~ "script completed after"

      lines = events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(&:jiffy.decode(&1, [:return_maps, null_term: nil]))
      names = Enum.map(lines, & &1["event"])

      for name <- ~w(vehicle_discovered picked allocated task_started condition_met task_finished released message script_started script_finished),
          do: assert(name in names, "no #{name} event")

      # Every line follows the catalogue: t_ms, event and exactly its fields.
      catalogue = Dolphin.Events.catalogue()

      for line <- lines do
        fields = catalogue[String.to_existing_atom(line["event"])] |> Enum.map(&Atom.to_string/1)
        assert Enum.sort(Map.keys(line)) == Enum.sort(["t_ms", "event" | fields])
        assert is_integer(line["t_ms"]) and line["t_ms"] >= 0
      end

      finished = Enum.find(lines, &(&1["event"] == "task_finished" and &1["kind"] == "test"))
      assert %{"name" => "survey", "result" => "stopped", "vehicle" => v} = finished
      assert is_integer(v)
      assert %{"result" => "done", "reason" => nil} = List.last(lines)
      # The task stopped after 2 s of clock time (at speed-up 20: 0.1 s of real time)
      # from the start of `during`, whose time runs from before its task's start.
      started = Enum.find(lines, &(&1["event"] == "task_started" and &1["kind"] == "during"))
      assert finished["t_ms"] - started["t_ms"] >= 2_000
      assert Dolphin.Clock.speedup() == 1
    end

    test "--for stops a script that runs for ever: status 0, vehicles hold", %{tmp_dir: dir} do
      path =
        script(dir, "patrol.exs", """
        use Dolphin.Script
        v = pick()
        forever do
          execute %{v => Dolphin.Engine.FakePlatform.task("patrol", duration: minutes(5))}
        end
        """)

      assert {0, out, ""} = main([path, "--fake", "1", "--for", "2s", "--speedup", "10"])
      assert out =~ "task 3 test \"patrol\"" or out =~ ~s(test "patrol" started)
      assert out =~ ~s(test "patrol" on vehicle 1: stopped)
      assert out =~ "script stopped after"
      assert out =~ "--for 2s is over"
    end

    test "--for: the events file reads as the history: tasks stopped, then vehicles released, then the script's end", %{tmp_dir: dir} do
      path =
        script(dir, "patrol2.exs", """
        use Dolphin.Script
        vs = pick(count: 2)
        forever do
          execute %{vs => Dolphin.Engine.concurrent([Dolphin.Engine.FakePlatform.task("a", duration: :infinity), Dolphin.Engine.FakePlatform.task("b", duration: :infinity)])}
        end
        """)

      events = Path.join(dir, "events.jsonl")
      assert {0, out, ""} = main([path, "--fake", "2", "--for", "2s", "--speedup", "10", "--events", events])
      lines = events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(&:jiffy.decode(&1, [:return_maps, null_term: nil]))
      names = Enum.map(lines, & &1["event"])

      finished = for %{"event" => "task_finished"} = e <- lines, do: e
      assert length(finished) == length(for "task_started" <- names, do: 1)
      assert Enum.all?(finished, &(&1["result"] == "stopped"))
      # The stop says why in words, not as an Erlang term.
      assert Enum.all?(finished, &(&1["reason"] == "stopped: the run's time (--for) is over")), inspect(finished)
      refute out =~ ":killed"
      assert out =~ ~s[test "a" on vehicle 1: stopped (the run's time (--for) is over)]

      released = Enum.find_index(names, &(&1 == "released"))
      assert released, "no released event"
      last_finished = names |> Enum.with_index() |> Enum.filter(&(elem(&1, 0) == "task_finished")) |> List.last() |> elem(1)
      assert last_finished < released, "released before a task stopped: #{inspect(names)}"
      assert List.last(names) == "script_finished"
      assert %{"result" => "stopped", "reason" => "stopped: the run's time (--for) is over"} = List.last(lines)
    end

    test "a failing script: status 1, what, where, why", %{tmp_dir: dir} do
      path =
        script(dir, "fails.exs", """
        use Dolphin.Script
        v = pick()

        execute %{v => Dolphin.Engine.FakePlatform.task("survey", duration: 10, result: {:fail, "motor failure"})}
        """)

      assert {1, _out, err} = main([path, "--fake", "1", "--quiet"])
      assert err =~ "fails.exs:4: execute failed: test \"survey\""
      assert err =~ "on vehicle 1 failed: motor failure"
    end

    test "an output file that cannot be written: bad usage (status 2), the option named, before anything runs", %{tmp_dir: dir} do
      path = script(dir, "hello.exs", "use Dolphin.Script\nmessage(\"hello\")\n")
      missing = Path.join(dir, "no_such_dir")

      for option <- ["--events", "--tlog", "--report"] do
        file = Path.join(missing, "out")
        assert {2, out, err} = main([path, "--sim", "1", option, file])
        assert err =~ "mix dolphin.run: #{option} #{file}: cannot create it: no such directory #{missing}\nusage: mix dolphin.run"
        assert out == ""
      end

      assert {2, "", err} = main([path, "--fake", "1", "--events", dir])
      assert err =~ "--events #{dir}: it is a directory, not a file"
      assert Dolphin.Clock.speedup() == 1
      refute File.exists?(missing)
    end

    test "--quiet prints only messages, errors and the summary", %{tmp_dir: dir} do
      path = script(dir, "quiet.exs", "use Dolphin.Script\nv = pick()\nmessage(\"hello\")\nrelease(v)\n")
      assert {0, out, ""} = main([path, "--fake", "1", "--quiet"])
      refute out =~ "picked"
      assert out =~ "message: hello"
      assert out =~ "script completed"
    end
  end

  if Code.ensure_loaded?(Dolphin.Sim) do
    @tag timeout: 120_000
    test "--sim N runs the script against simulated vehicles over UDP", %{tmp_dir: dir} do
      path =
        script(dir, "sim.exs", """
        use Dolphin.Script
        vs = pick(count: 2, type: :uav, timeout: seconds(30))
        for v <- vs, do: message("vehicle \#{inspect(v)} battery \#{inspect(battery(v))}")
        release(vs)
        """)

      tlog = Path.join(dir, "run.tlog")
      assert {0, out, ""} = main([path, "--sim", "2", "--speedup", "10", "--tlog", tlog])
      assert out =~ "2 simulated vehicle(s) [1, 2]"
      assert out =~ "vehicle 1 discovered (uav copter)"
      assert out =~ ~r/message: vehicle #Vehicles<\[1\]> battery (1\.0|0\.\d+|nil)/
      assert File.stat!(tlog).size > 0
    end

    @tag timeout: 120_000
    test "--fleet FILE gives the vehicles what they carry by system id: a pick for a side-scan sonar gets vehicle 2; a bad file names its problem", %{tmp_dir: dir} do
      path =
        script(dir, "sonar.exs", """
        use Dolphin.Script
        v = pick(payload: :sidescan, timeout: seconds(30))
        message("sonar on \#{inspect(v)}")
        release(v)
        """)

      fleet = Path.join(dir, "fleet.json")
      File.write!(fleet, ~s({"vehicles": [{"id": 2, "payloads": ["sidescan"], "position": [40.444233, -7.375234, 820]}]}))
      assert {0, out, ""} = main([path, "--sim", "2", "--speedup", "10", "--no-tlog", "--fleet", fleet])
      assert out =~ "payloads from #{fleet}: 2 [:sidescan]"
      assert out =~ "message: sonar on #Vehicles<[2]>"
      # Given for the run only.
      assert Dolphin.Vehicles.given_payloads(2) == []

      # The pre-flight check's stand-ins carry it too: without the file, no vehicle has a sonar.
      assert {1, out, _} = main([path, "--sim", "2", "--speedup", "10", "--no-tlog"])
      assert out =~ "the pre-flight check found errors: nothing flies"

      File.write!(fleet, ~s({"vehicles": [{"id": 2, "payloads": ["side scan"], "position": [40.4, -7.3, 820]}]}))
      assert {1, _, err} = main([path, "--sim", "2", "--speedup", "10", "--no-tlog", "--no-check", "--fleet", fleet])
      assert err =~ "--fleet #{fleet}"
      assert err =~ ~s|payload names are lower-case letters, digits and _ (as in "thermal_camera"), got "side scan"|
    end

    @tag timeout: 120_000
    test "one clock for the events and the summary: the run's, from before its vehicles started", %{tmp_dir: dir} do
      path = script(dir, "wait.exs", "use Dolphin.Script\npick(timeout: seconds(60))\nforever do\n  pause(seconds(1))\nend\n")
      events = Path.join(dir, "events.jsonl")
      assert {0, out, ""} = main([path, "--sim", "1", "--speedup", "20", "--for", "10s", "--no-tlog", "--no-check", "--events", events])

      at = fn name -> events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(&:jiffy.decode(&1, [:return_maps])) |> Enum.find(&(&1["event"] == name)) |> Map.fetch!("t_ms") end
      started = at.("script_started")
      finished = at.("script_finished")
      # The simulated vehicle booted before the script started.
      assert started > 0
      seconds = &Dolphin.Console.Format.seconds/1
      assert out =~ "script stopped after #{seconds.(finished)} of clock time (--for 10s is over, counted from the script's start at #{seconds.(started)}): running tasks were stopped, vehicles hold"
    end

    @tag timeout: 120_000
    test "--tlog FILE replaces a file that is there, and says so: the log holds one run", %{tmp_dir: dir} do
      path = script(dir, "hover.exs", "use Dolphin.Script\nv = pick(timeout: seconds(30))\nexecute(wait_for(position(v) != nil))\npause(seconds(5))\nrelease(v)\n")
      tlog = Path.join(dir, "run.tlog")
      File.write!(tlog, "an older file")

      for _ <- 1..2 do
        Dolphin.Test.GroundStation.forget_vehicles()
        assert {0, out, ""} = main([path, "--sim", "1", "--speedup", "20", "--tlog", tlog])
        assert out =~ "telemetry log: #{tlog} (replaces the file that was there)"
      end

      # Nothing of the older file, nor of the first run (whose vehicle booted
      # anew in the second: its boot clock would go back).
      {:ok, log} = Dolphin.Report.FlightLog.read_file(tlog)
      assert log.stats.bytes_skipped == 0
      assert [_one] = Dolphin.Report.FlightLog.runs(log)
      boots = for {_ts, %{message: %Dolphin.MAVLink.Ardupilotmega.GlobalPositionInt{time_boot_ms: t}}} <- elem(Dolphin.MAVLink.Tlog.read(Dolphin.MAVLink.Tlog.reader(), File.read!(tlog)), 0), do: t
      assert boots != [] and boots == Enum.sort(boots)
    end
  end
end
