defmodule Dolphin.ReportTest do
  # Captures the standard error, the VM's one device, which compiling a
  # script (in the async tests that run examples) swaps too: not async.
  use ExUnit.Case, async: false

  import ExUnit.CaptureIO

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.{Frame, Tlog}
  alias Dolphin.Report
  alias Dolphin.Report.Error

  @moduletag :tmp_dir

  @t0 1_800_000_000_000_000
  @lat0 404_442_330
  @lon0 -73_752_340
  # About 1 m in degrees × 10⁷ at that latitude.
  @m 90

  # Two vehicles over 60 s at 2 Hz, seen as a ground station's log sees them:
  # vehicle 1 flies 100 m north, vehicle 2 100 m east, each after an upload of
  # three items; vehicle 1 arms and goes AUTO at 5 s, takes a photo at 20 s
  # and reaches item 1 at 30 s.
  defp tlog(dir, name \\ "run.tlog") do
    path = Path.join(dir, name)
    File.write!(path, tlog_bytes())
    path
  end

  # `shift_us` later on the log's clock; `reboot_at_s`: vehicle 2's boot clock
  # starts again then (a reboot in flight).
  defp tlog_bytes(shift_us \\ 0, reboot_at_s \\ nil) do
    upload =
      for v <- [1, 2] do
        count = %M.MissionCount{target_system: v, target_component: 1, count: 3}

        items =
          for {seq, {n, e}} <- Enum.with_index([{0, 0}, {100, 0}, {0, 0}], &{&2, &1}) do
            {n, e} = if v == 2, do: {e, n}, else: {n, e}
            %M.MissionItemInt{target_system: v, target_component: 1, seq: seq, frame: 5, command: 16, x: @lat0 + n * @m, y: @lon0 + e * @m, z: 850.0}
          end

        Enum.map([count | items], &{2_000_000, 255, 190, &1})
      end

    telemetry =
      for half <- 0..119, v <- [1, 2] do
        t = half / 2
        armed = t >= 5
        up = round(min(max(t - 5, 0) * 4, 50))
        along = round(min(max(t - 10, 0) * 5, 100) * @m)
        {lat, lon} = if v == 1, do: {@lat0 + along, @lon0}, else: {@lat0, @lon0 + along}
        # Before its position estimate has an origin ArduPilot reports 0, 0 (SITL's first seconds): no place.
        {lat, lon} = if t < 2, do: {0, 0}, else: {lat, lon}
        ts = round(t * 1_000_000) + v * 1_000

        boot_s = if reboot_at_s && v == 2 && t >= reboot_at_s, do: t - reboot_at_s, else: t

        [{ts, v, 1, %M.GlobalPositionInt{time_boot_ms: round(boot_s * 1000), lat: lat, lon: lon, alt: 820_000 + up * 1000, relative_alt: up * 1000, vx: 500, vy: 0}}] ++
          if rem(half, 2) == 0 do
            [
              {ts + 1, v, 1, %M.Heartbeat{type: 2, autopilot: 3, base_mode: if(armed, do: 0x91, else: 0x11), custom_mode: if(armed, do: 3, else: 0), mavlink_version: 3}},
              {ts + 2, v, 1, %M.SysStatus{battery_remaining: 100 - div(half, 3)}},
              {ts + 3, v, 1, %M.HomePosition{latitude: @lat0, longitude: @lon0, altitude: 820_000}}
            ]
          else
            []
          end
      end

    extra = [
      {20_000_100, 1, 100, %M.CameraImageCaptured{lat: @lat0 + 50 * @m, lon: @lon0, image_index: 1, capture_result: 1}},
      {30_000_100, 1, 1, %M.MissionItemReached{seq: 1}},
      {31_000_100, 1, 1, %M.Statustext{severity: 6, text: "Reached waypoint #1"}}
    ]

    (List.flatten(upload) ++ List.flatten(telemetry) ++ extra)
    |> Enum.sort_by(&elem(&1, 0))
    |> Enum.map_reduce(%{}, fn {ts, sysid, compid, msg}, seqs ->
      seq = Map.get(seqs, {sysid, compid}, 0)
      {Tlog.record(@t0 + shift_us + ts, Frame.encode(msg, sysid: sysid, compid: compid, seq: rem(seq, 256))), Map.put(seqs, {sysid, compid}, seq + 1)}
    end)
    |> elem(0)
    |> IO.iodata_to_binary()
  end

  # The run's events, their clock starting `lead_s` before the log's.
  # `rate`: the vehicles' pace against the clock of the events (below 1: they fell behind it).
  defp events(dir, lead_s \\ 1.0, name \\ "run.jsonl", edit \\ & &1, rate \\ 1.0) do
    ms = fn t -> round((t / rate + lead_s) * 1000) end

    lines =
      [
        %{t_ms: ms.(0.5), event: "vehicle_discovered", vehicle: 1, type: "uav"},
        %{t_ms: ms.(0.5), event: "vehicle_discovered", vehicle: 2, type: "uav"},
        %{t_ms: ms.(1), event: "script_started", script: "survey.exs"},
        %{t_ms: ms.(1.5), event: "task_started", run: 1, task_id: 1, parent_id: nil, kind: "concurrent", name: "both", vehicle: nil},
        %{t_ms: ms.(1.5), event: "task_started", run: 1, task_id: 2, parent_id: 1, kind: "mission", name: "North", vehicle: 1},
        %{t_ms: ms.(1.5), event: "task_started", run: 1, task_id: 3, parent_id: 1, kind: "mission", name: "East", vehicle: 2},
        %{t_ms: ms.(5), event: "armed", vehicle: 1},
        %{t_ms: ms.(5), event: "mode_changed", vehicle: 1, mode: "auto"},
        %{t_ms: ms.(5), event: "armed", vehicle: 2},
        %{t_ms: ms.(5), event: "mode_changed", vehicle: 2, mode: "auto"},
        %{t_ms: ms.(12), event: "condition_met", run: 1, task_id: 2, condition: "battery(v) < 0.9", branch: nil},
        %{t_ms: ms.(30), event: "mission_item_reached", vehicle: 1, seq: 1},
        %{t_ms: ms.(40), event: "task_finished", run: 1, task_id: 3, parent_id: 1, kind: "mission", name: "East", vehicle: 2, result: "failed", reason: "the vehicle left its mission"},
        %{t_ms: ms.(55), event: "task_finished", run: 1, task_id: 2, parent_id: 1, kind: "mission", name: "North", vehicle: 1, result: "done", reason: nil},
        %{t_ms: ms.(55), event: "message", text: "all done"},
        %{t_ms: ms.(58), event: "script_finished", script: "survey.exs", result: "failed", reason: "East failed"}
      ]
      |> edit.()

    path = Path.join(dir, name)
    File.write!(path, Enum.map(lines, &[:jiffy.encode(Map.new(&1, fn {k, v} -> {k, if(v == nil, do: :null, else: v)} end)), ?\n]))
    path
  end

  defp count(html, pattern), do: length(Regex.scan(pattern, html))

  test "a report of a log and its events", %{tmp_dir: dir} do
    out = Path.join(dir, "report.html")
    assert {:ok, summary} = Report.write(tlog(dir), events(dir), out)
    assert %{vehicles: [1, 2], path: ^out, events: 16, events_skipped: 0, bytes_skipped: 0, script_result: "failed"} = summary
    assert_in_delta summary.speedup, 1.0, 0.01
    assert_in_delta summary.span_s, 59.5, 0.1
    html = File.read!(out)
    assert byte_size(html) == summary.bytes

    # Map: a track and a planned path per vehicle, home, a photo, take-offs.
    assert count(html, ~r/<polyline class="flown" data-vehicle="1"/) == 1
    assert count(html, ~r/<polyline class="flown" data-vehicle="2"/) == 1
    assert count(html, ~r/<polyline class="planned"/) == 2
    assert count(html, ~r/class="photo"/) == 1
    assert count(html, ~r/class="takeoff"/) == 2
    assert count(html, ~r/class="home"/) == 2
    assert html =~ ~s(class="scale-bar") and html =~ ~s(class="north-arrow")

    # Time line: the two platform tasks with their results and the reason.
    assert html =~ ~r/data-vehicle="1" data-name="North" data-kind="mission" data-result="done"/
    assert html =~ ~r/data-vehicle="2" data-name="East" data-kind="mission" data-result="failed"/
    assert html =~ "failed — the vehicle left its mission"
    # The condition is under task 1 > 2, whose only vehicle is 1: on its lane.
    assert html =~ "condition met: battery(v) &lt; 0.9"

    # Plots and summary, which says what each vehicle is (its heartbeat's type and airframe).
    for plot <- ~w(battery height speed link), do: assert(html =~ ~s(class="plot plot-#{plot}"))
    assert html =~ ~r{<td><span class="swatch"></span>1</td><td>uav copter</td>}
    # Each flew 100 m: the 0, 0 reported before a position fix is no place it went to.
    assert html =~ ~r{<td><span class="swatch"></span>1</td><td>uav copter</td><td>[^<]+</td><td>100 m</td>}
    # The distance between the two over time, against the least separation.
    assert [_] = Regex.scan(~r/<svg class="plot separation"/, html)
    assert html =~ ~r/least [\d.]+ m at [^,]+, vehicles [12] and [12]/
    assert html =~ ~s(id="script-result">failed)
    assert html =~ "<b>East</b>: the vehicle left its mission"

    # Self-contained: nothing to fetch.
    refute html =~ ~r/<script[^>]+src|<link|<img|url\(|@import/
    assert html |> String.replace("http://www.w3.org/2000/svg", "") |> String.contains?("http") == false
  end

  test "the events are placed on the log's time line by what both record", %{tmp_dir: dir} do
    {:ok, log} = Dolphin.Report.FlightLog.read_file(tlog(dir))
    {:ok, events, 0} = Dolphin.Report.Events.read_file(events(dir, 7.5))
    assert {:ok, {scale, offset}} = Dolphin.Report.Events.align(events, Dolphin.Report.Model.anchors(log), "run.jsonl")
    assert_in_delta scale, 1.0, 0.05
    assert_in_delta offset, -7.5, 0.6
  end

  test "events with no arming, mode or item are placed by the vehicles' discovery, when starting the run took long", %{tmp_dir: dir} do
    {:ok, log} = Dolphin.Report.FlightLog.read_file(tlog(dir))
    # A short look at the vehicles (nothing armed, no mode changed): the links took 45 s of clock time to start.
    quiet = fn lines -> Enum.reject(lines, &(&1.event in ["armed", "mode_changed", "mission_item_reached"])) end
    {:ok, events, 0} = Dolphin.Report.Events.read_file(events(dir, 45.0, "look.jsonl", quiet))
    assert {:ok, {1.0, offset}} = Dolphin.Report.Events.align(events, Dolphin.Report.Model.anchors(log), "look.jsonl")
    # Discovered half a second into the log (its first heartbeat: at 0.5 s too).
    assert_in_delta offset, -45.0, 1.0
  end

  test "events of vehicles that fell behind the clock's speed-up (a loaded machine) are placed by rate and origin", %{tmp_dir: dir} do
    {:ok, log} = Dolphin.Report.FlightLog.read_file(tlog(dir))
    # The clock ran at the speed-up asked for, the vehicles at 0.6 of it: 5 s of theirs is 8.3 s of the events'.
    {:ok, events, 0} = Dolphin.Report.Events.read_file(events(dir, 7.5, "slow.jsonl", & &1, 0.6))
    assert {:ok, {scale, offset}} = Dolphin.Report.Events.align(events, Dolphin.Report.Model.anchors(log), "slow.jsonl")
    assert_in_delta scale, 0.6, 0.05
    assert_in_delta offset, -0.6 * 7.5, 0.6

    # The report is written, with each task where the vehicles flew it.
    out = Path.join(dir, "slow.html")
    assert {:ok, _} = Report.write(tlog(dir), Path.join(dir, "slow.jsonl"), out)
    assert File.read!(out) =~ "<b>East</b>: the vehicle left its mission"
  end

  describe "a pace that swung during the run" do
    # The vehicles' pace against the clock asked for, by 60 s of the events'
    # clock: 0.6 of it, then all of it, and so on (ArduCopter SITL beside
    # other work); the log's seconds at event second e.
    defp swung(e), do: swung(e, 0.0, 0.0)
    defp swung(e, from, t) when e - from <= 60, do: t + (e - from) * pace(from)
    defp swung(e, from, t), do: swung(e, from + 60, t + 60 * pace(from))
    defp pace(from), do: if(rem(round(from / 60), 2) == 0, do: 0.6, else: 1.0)

    # Three vehicles armed, in AUTO and reaching an item every 7 s for ten
    # minutes of the events' clock, each anchor logged a heartbeat late or
    # early (up to half a second); `edit` changes the events.
    defp swinging_run(edit \\ & &1) do
      :rand.seed(:exsss, {7, 7, 7})
      late = fn -> :rand.uniform() - 0.5 end

      per_vehicle =
        for v <- 1..3 do
          items = for {e, seq} <- Enum.with_index(Stream.iterate(10.0 + v, &(&1 + 7)) |> Enum.take_while(&(&1 < 590)), 1), do: {e, seq}
          events = [%{"event" => "armed", "vehicle" => v, "t_ms" => (5 + v) * 1000}, %{"event" => "mode_changed", "vehicle" => v, "mode" => "auto", "t_ms" => (6 + v) * 1000}]
          events = events ++ for({e, seq} <- items, do: %{"event" => "mission_item_reached", "vehicle" => v, "seq" => seq, "t_ms" => round(e * 1000)})
          log = %{arming: [swung(5.0 + v) + late.()], modes: [{swung(6.0 + v) + late.(), :auto}], reached: for({e, seq} <- items, do: {swung(e) + late.(), seq})}
          {v, events, log}
        end

      events = (Enum.flat_map(per_vehicle, &elem(&1, 1)) ++ [%{"event" => "script_finished", "t_ms" => 595_000}]) |> edit.() |> Enum.sort_by(& &1["t_ms"])

      log = %{
        vehicles: [1, 2, 3],
        span_s: swung(600.0),
        speedup: 10,
        arming: Map.new(per_vehicle, fn {v, _, l} -> {v, l.arming} end),
        modes: Map.new(per_vehicle, fn {v, _, l} -> {v, l.modes} end),
        reached: Map.new(per_vehicle, fn {v, _, l} -> {v, l.reached} end),
        heard: %{},
        cut: false
      }

      {events, log}
    end

    test "its events are placed through the anchors themselves, each within a heartbeat of where the vehicles were" do
      {events, log} = swinging_run()
      assert {:ok, {:piecewise, knots} = timeline} = Dolphin.Report.Events.align(events, log, "swung.jsonl")
      assert length(knots) > 200

      for %{"t_ms" => t} <- events do
        assert_in_delta Dolphin.Report.Events.place(timeline, t), swung(t / 1000), 1.5
      end
    end

    test "another run's events are still refused" do
      {events, log} = swinging_run(fn events -> Enum.map(events, &%{&1 | "t_ms" => :rand.uniform(600_000)}) end)
      assert {:error, %Error{reason: :events_mismatch, detail: detail}} = Dolphin.Report.Events.align(events, log, "other.jsonl")
      assert detail =~ "line up with the telemetry log"
    end
  end

  test "without events: the log alone", %{tmp_dir: dir} do
    out = Path.join(dir, "report.html")
    assert {:ok, %{events: nil, script_result: nil}} = Report.write(tlog(dir), nil, out, title: "Survey <north>")
    html = File.read!(out)
    assert html =~ "<h1>Survey &lt;north&gt;</h1>"
    assert html =~ "no events file"
    assert count(html, ~r/<polyline class="flown"/) == 2
    refute html =~ ~s(class="task")
    # The mode changes come from the log's heartbeats.
    assert html =~ "mode auto"
  end

  test "a damaged log gives a report of what could be read, and says what was skipped", %{tmp_dir: dir} do
    bytes = tlog_bytes()
    half = div(byte_size(bytes), 2)
    # Garbage in the middle, a flipped byte (bad checksum), the end cut off.
    <<a::binary-size(half), b::binary>> = bytes
    <<b1::binary-size(100), x, b2::binary>> = b
    damaged = a <> :crypto.strong_rand_bytes(300) <> b1 <> <<Bitwise.bxor(x, 0xFF)>> <> b2
    damaged = binary_part(damaged, 0, byte_size(damaged) - 7)
    path = Path.join(dir, "damaged.tlog")
    File.write!(path, damaged)

    out = Path.join(dir, "report.html")
    assert {:ok, summary} = Report.write(path, events(dir), out)
    assert summary.vehicles == [1, 2]
    assert summary.bytes_skipped >= 300
    html = File.read!(out)
    assert html =~ ~r/The telemetry log is damaged: \d+ of \d+ bytes were skipped \(.*truncated 1/
    assert count(html, ~r/<polyline class="flown"/) == 2
  end

  test "unreadable event lines are skipped and counted", %{tmp_dir: dir} do
    path = events(dir)
    File.write!(path, "{\"t_ms\": 3, \"event\": \"arm\n" <> File.read!(path) <> "not json\n")
    out = Path.join(dir, "report.html")
    assert {:ok, %{events: 16, events_skipped: 2}} = Report.write(tlog(dir), path, out)
    assert File.read!(out) =~ "2 line(s) of the events file could not be read"
  end

  describe "events of another run are refused" do
    test "its vehicles are not in the log", %{tmp_dir: dir} do
      path = events(dir, 1.0, "other.jsonl", fn lines -> Enum.map(lines, &if(&1[:vehicle] == 2, do: %{&1 | vehicle: 7}, else: &1)) end)
      assert {:error, %Error{reason: :events_mismatch, detail: detail} = e} = Report.write(tlog(dir), path, Path.join(dir, "r.html"))
      assert detail =~ "vehicles 7 are not in the telemetry log"
      assert Exception.message(e) =~ "the events do not belong to the telemetry log"
      refute File.exists?(Path.join(dir, "r.html"))
    end

    test "its arming, modes and items do not line up with the log's", %{tmp_dir: dir} do
      scatter = fn lines ->
        Enum.map(lines, fn
          %{event: "armed", vehicle: 1} = e -> %{e | t_ms: 30_000}
          %{event: "mode_changed", vehicle: 2} = e -> %{e | t_ms: 50_000}
          %{event: "mission_item_reached"} = e -> %{e | t_ms: 2_000}
          e -> e
        end)
      end

      path = events(dir, 1.0, "other.jsonl", scatter)
      assert {:error, %Error{reason: :events_mismatch, detail: detail}} = Report.write(tlog(dir), path, Path.join(dir, "r.html"))
      assert detail =~ "line up with the telemetry log"
    end

    test "its time does not overlap the log's", %{tmp_dir: dir} do
      later = fn lines -> Enum.map(lines, &%{&1 | t_ms: &1.t_ms + 3_600_000}) |> Enum.reject(&(&1.event in ["armed", "mode_changed", "mission_item_reached"])) end
      path = events(dir, 1.0, "other.jsonl", later)
      assert {:error, %Error{reason: :events_mismatch, detail: detail}} = Report.write(tlog(dir), path, Path.join(dir, "r.html"))
      assert detail =~ "overlap"
    end

    test "its script ended long before the log does", %{tmp_dir: dir} do
      # A shorter run of the same vehicles, alike at first: armed and in AUTO at 5 s.
      shorter = fn lines ->
        lines
        |> Enum.filter(&(&1.t_ms <= 7_000 or &1.event == "script_finished"))
        |> Enum.map(&if(&1.event == "script_finished", do: %{&1 | t_ms: 7_000}, else: &1))
      end

      path = events(dir, 1.0, "other.jsonl", shorter)
      assert {:error, %Error{reason: :events_mismatch, detail: detail}} = Report.write(tlog(dir), path, Path.join(dir, "r.html"))
      assert detail =~ "its script ended"
    end
  end

  describe "a log that holds two runs" do
    # A second run of the same vehicles appended two minutes after the first
    # began: the ground station recorded nothing in between, and the
    # vehicles' boot clocks started again.
    setup %{tmp_dir: dir} do
      path = Path.join(dir, "two.tlog")
      File.write!(path, [tlog_bytes(), tlog_bytes(120_000_000)])
      %{two: path}
    end

    test "is reported one run at a time, the last unless --run says, and says so", %{tmp_dir: dir, two: two} do
      out = Path.join(dir, "r.html")
      # The second run's events line up with the second run alone.
      assert {:ok, summary} = Report.write(two, events(dir), out)
      assert %{runs: 2, run: 2, vehicles: [1, 2], events: 16} = summary
      assert_in_delta summary.span_s, 60.0, 1.0
      html = File.read!(out)
      assert html =~ "The telemetry log holds 2 runs"
      assert html =~ "this report shows run 2 of 2 alone, the last"
      assert count(html, ~r/<polyline class="flown"/) == 2

      assert {:ok, %{runs: 2, run: 1, span_s: span}} = Report.write(two, nil, out, run: 1)
      assert_in_delta span, 60.0, 1.0
      assert {:error, %Error{reason: :no_such_run} = e} = Report.write(two, nil, out, run: 3)
      assert Exception.message(e) == "no such run in the telemetry log: #{two}: it holds 2 runs, there is no run 3"
    end

    test "a vehicle that reboots while the ground station goes on recording is one run", %{tmp_dir: dir} do
      path = Path.join(dir, "reboot.tlog")
      File.write!(path, tlog_bytes(0, 30))
      assert {:ok, %{runs: 1, run: 1, span_s: span}} = Report.write(path, events(dir), Path.join(dir, "r.html"))
      assert_in_delta span, 60.0, 1.0
      refute File.read!(Path.join(dir, "r.html")) =~ "holds 2 runs"
    end

    test "mix dolphin.report says which run it reports", %{tmp_dir: dir, two: two} do
      out = capture_io(fn -> Mix.Tasks.Dolphin.Report.run([two, "--events", events(dir), "-o", Path.join(dir, "r.html")]) end)
      assert out =~ "the telemetry log holds 2 runs (the vehicles' clocks started again after the ground station had stopped recording): this report is of run 2, the last, alone (--run N for another)"
      out = capture_io(fn -> Mix.Tasks.Dolphin.Report.run([two, "--run", "1", "-o", Path.join(dir, "r.html")]) end)
      assert out =~ "this report is of run 1, alone"
    end
  end

  test "a file with nothing readable in it is an error, not an empty report", %{tmp_dir: dir} do
    out = Path.join(dir, "r.html")
    noise = Path.join(dir, "noise.bin")
    File.write!(noise, :crypto.strong_rand_bytes(2000))
    assert {:error, %Error{reason: :no_frames} = e} = Report.write(noise, nil, out)
    assert Exception.message(e) == "no MAVLink frame in the telemetry log: #{noise}: none of its 2000 bytes is a telemetry-log record (a .tlog as mix dolphin.run writes it?)"
    empty = Path.join(dir, "empty")
    File.write!(empty, "")
    assert {:error, %Error{reason: :no_frames, detail: "the file is empty"}} = Report.write(empty, nil, out)

    assert {:error, %Error{reason: :no_events} = e} = Report.write(tlog(dir), noise, out)
    assert Exception.message(e) =~ ~r/^no event in the events file: #{Regex.escape(noise)}: none of its \d+ line\(s\) is an event/
    assert {:error, %Error{reason: :no_events, detail: "the file is empty"}} = Report.write(tlog(dir), empty, out)
    refute File.exists?(out)
  end

  test "errors: no log, no vehicle in it, nowhere to write", %{tmp_dir: dir} do
    assert {:error, %Error{reason: :tlog_unreadable}} = Report.write(Path.join(dir, "missing.tlog"), nil, Path.join(dir, "r.html"))
    # Frames, but only a ground station's.
    gcs = Path.join(dir, "gcs.tlog")
    File.write!(gcs, for(i <- 0..9, do: Tlog.record(@t0 + i * 1_000_000, Frame.encode(%M.Heartbeat{type: 6, autopilot: 8, mavlink_version: 3}, sysid: 255, compid: 190, seq: i))))
    assert {:error, %Error{reason: :no_vehicles}} = Report.write(gcs, nil, Path.join(dir, "r.html"))
    assert {:error, %Error{reason: :events_unreadable}} = Report.write(tlog(dir), Path.join(dir, "missing.jsonl"), Path.join(dir, "r.html"))
    assert {:error, %Error{reason: :write_failed}} = Report.write(tlog(dir), nil, Path.join([dir, "no", "such", "r.html"]))
  end

  describe "mix dolphin.report" do
    test "writes the report beside the log, or where -o says", %{tmp_dir: dir} do
      log = tlog(dir)
      ev = events(dir)
      out = capture_io(fn -> Mix.Tasks.Dolphin.Report.run([log, "--events", ev]) end)
      assert out =~ "report: #{Path.join(dir, "run.html")}"
      assert out =~ "2 vehicle(s)"
      assert out =~ "16 events"
      assert File.exists?(Path.join(dir, "run.html"))

      other = Path.join(dir, "other.html")
      capture_io(fn -> Mix.Tasks.Dolphin.Report.run([log, "-o", other]) end)
      assert File.exists?(other)
    end

    test "-o - writes the page to standard output, and what it holds to standard error", %{tmp_dir: dir} do
      log = tlog(dir)
      err = capture_io(:stderr, fn -> send(self(), {:page, capture_io(fn -> Mix.Tasks.Dolphin.Report.run([log, "-o", "-"]) end)}) end)
      assert_received {:page, "<!DOCTYPE html>" <> _ = page}
      assert page =~ "</html>"
      assert err =~ ~r/^report: standard output \(\d+ KiB\): 2 vehicle\(s\)/
      refute File.exists?("-")
    end

    test "usage and input errors", %{tmp_dir: dir} do
      assert_raise Mix.Error, ~r/usage: mix dolphin.report/, fn -> Mix.Tasks.Dolphin.Report.run([]) end
      assert_raise Mix.Error, ~r/unknown or malformed option --bogus/, fn -> Mix.Tasks.Dolphin.Report.run(["x.tlog", "--bogus"]) end
      assert_raise Mix.Error, ~r/cannot read the telemetry log/, fn -> Mix.Tasks.Dolphin.Report.run([Path.join(dir, "none.tlog")]) end
      missing = Path.join(dir, "missing")
      e = assert_raise Mix.Error, fn -> Mix.Tasks.Dolphin.Report.run([tlog(dir), "-o", Path.join(missing, "r.html")]) end
      assert e.message =~ "dolphin.report: -o #{missing}/r.html: cannot create it: no such directory #{missing}\nusage: mix dolphin.report"
      assert e.mix == 2
      e = assert_raise Mix.Error, fn -> Mix.Tasks.Dolphin.Report.run([tlog(dir), "--run", "0"]) end
      assert {e.message, e.mix} == {"dolphin.report: --run takes a run's number, from 1, got 0\nusage: mix dolphin.report RUN.tlog [--events RUN.jsonl] [-o REPORT.html] [--run N]", 2}
    end
  end
end
