defmodule Dolphin.SITL.AirframesTest do
  # Planes, rovers, boats and submarines on their own ArduPilot firmware
  # (ArduPlane, ArduRover, ArduSub SITL): each flies a mission of the
  # commands its airframe flies, start to end, then a second one that is
  # stopped half way and leaves it holding as its airframe holds
  # (docs/ardupilot.md, "Other airframes"). Runs SITL processes and changes
  # the clock's speed-up: not async.
  use ExUnit.Case, async: false

  alias Dolphin.{Engine, Geo, SITL, Vehicles}
  alias Dolphin.Geo.Location
  # Used only by the tests of the firmwares found: no warning when none is
  # (and the helpers below are public for the same reason).
  alias Dolphin.Mission, warn: false
  alias Dolphin.Mission.Command, as: C, warn: false
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Test.{FrameRecorder, Wait}

  @moduletag :sitl
  @moduletag timeout: 600_000
  @speedup 10

  setup do
    Dolphin.Fleet.set_source({Dolphin.Fleet.MAVLinkSource, nil})
    Dolphin.Clock.set_speedup(@speedup)

    on_exit(fn ->
      Dolphin.Fleet.release_all(Dolphin.Fleet, self())
      Dolphin.Clock.set_speedup(1)
    end)

    :ok
  end

  # `fun` given the vehicle (its id, its home, a function giving the items
  # it reported reached so far, and a recorder of its
  # frames stamped with its own clock) on `backend`, the built-in simulator or
  # SITL, which is stopped after.
  def on_backend(backend, airframe, kind, fun) do
    {start, stop} = if backend == :sitl, do: {&SITL.start/2, &SITL.stop/1}, else: {&Dolphin.Sim.Local.start/2, &Dolphin.Sim.Local.stop/1}
    {:ok, recorder} = FrameRecorder.start_link()
    {:ok, fleet} = start.([{airframe, 1}], forward: [FrameRecorder.endpoint(recorder)])

    try do
      {id, home, seen} = vehicle(fleet, kind)
      fun.({id, home, {seen, recorder}})
    after
      Dolphin.Fleet.release_all(Dolphin.Fleet, self())
      stop.(fleet)
    end
  end

  def vehicle(fleet, kind) do
    [id] = fleet.sysids
    Wait.until(fn -> match?({:ok, %{home: %Location{}, position: %Location{}}}, Vehicles.view(id)) end, 3_000)
    {:ok, view} = Vehicles.view(id)
    assert {view.type, view.airframe, view.mav_type} == kind
    {:ok, _} = Dolphin.Fleet.pick(Dolphin.Fleet, self(), id: id)
    {id, view.home, reached(id)}
  end

  def fly(mission, id), do: Engine.run(Engine.on(mission, [id]))

  # Flies `mission` and says how it went: the result, the items reported
  # reached, the time from arming to the end in the vehicle's own clock (a
  # loaded machine slows SITL's down, not the mission's), and the vehicle's
  # view then.
  def flown(mission, id, {seen, recorder}) do
    Dolphin.Events.subscribe()
    result = fly(mission, id)
    events = drain()
    own = for {t, ^id, m} <- FrameRecorder.frames(recorder), t != nil, do: {t, m}
    armed_at = Enum.find_value(own, fn {t, m} -> match?(%M.Heartbeat{base_mode: b} when b >= 128, m) && t end)
    {done_at, _} = List.last(own)
    reached = for({:dolphin, :events, %{event: :mission_item_reached, vehicle: ^id, seq: s}} <- events, uniq: true, do: s) ++ seen.()
    {:ok, view} = Vehicles.view(id)
    texts = for {_, text} <- Vehicles.status_texts(id), do: text
    %{result: result, reached: Enum.sort(Enum.uniq(reached)), driving_ms: armed_at && done_at - armed_at, view: view, texts: texts}
  end

  # The built-in simulator and ArduPilot flew it alike: the same items
  # reported, the same end, in about the same time (within 35 %: the
  # simulator does not model the corners, the currents, the drift).
  def alike(sim, sitl, what) do
    table = "#{what}: simulator #{inspect(Map.drop(sim, [:view, :texts]))}, ArduPilot #{inspect(Map.drop(sitl, [:view, :texts]))}"
    assert sim.result == sitl.result, table
    assert sim.reached == sitl.reached, table
    assert {sim.view.mode, sim.view.armed?} == {sitl.view.mode, sitl.view.armed?}, table
    assert abs(sim.driving_ms - sitl.driving_ms) <= 0.35 * sitl.driving_ms, table
  end

  # Stopped after `ms` of clock time; the mode it holds in, once the heartbeat says so.
  def stopped(mission, id, ms, mode) do
    assert {:ok, :done} = Engine.run(Engine.during(ms, Engine.on(mission, [id])))
    Wait.until(fn -> match?({:ok, %{mode: ^mode}}, Vehicles.view(id)) end, 500)
    {:ok, view} = Vehicles.view(id)
    view
  end

  def distance(%Location{} = a, %Location{} = b), do: Geo.distance(Geo.location(a.lat, a.lon), Geo.location(b.lat, b.lon))

  def reached(id) do
    Dolphin.Events.subscribe()
    fn -> for({:dolphin, :events, %{event: :mission_item_reached, vehicle: ^id, seq: seq}} <- drain(), do: seq) end
  end

  def drain do
    receive do
      m -> [m | drain()]
    after
      0 -> []
    end
  end

  missing = for airframe <- [:plane, :rover, :boat, :sub], not SITL.available?(airframe), do: airframe

  if missing != [] do
    IO.puts("SITL tests of the #{Enum.join(missing, ", ")} skipped: no SITL binary for them (put ArduPilot's SITL binaries in ARDUPILOT_SITL_DIR, or ../shared/sitl/ beside the project)")
  end

  if SITL.available?(:plane) do
    test "a plane takes off at its pitch, circles its loiter, lands through its landing sequence and disarms; stopped, it circles (LOITER); the simulator's alike" do
      circuit = fn home ->
        Mission.new("Circuit", [
          C.home(home),
          C.take_off(Location.at_height(home, home.h + 60), 15),
          C.move(500, 0, 0),
          C.move_and_loiter_turns(0, 0, 0, 1, 80),
          C.move(-300, 0, -20),
          C.return_home_and_land()
        ])
      end

      [sim, sitl] =
        for backend <- [:sim, :sitl] do
          on_backend(backend, :plane, {:uav, :plane, 1}, fn {id, home, seen} ->
            # Items: 1 take-off, 2 waypoint, 3 loiter, 4 a waypoint back, 5 DO_LAND_START, 6 the approach (400 m out, 28 m up), 7 NAV_LAND.
            assert [_, %{command: 22, param1: 15.0}, _, _, _, %{command: 189}, %{command: 16} = approach, %{command: 21}] = Mission.to_items(circuit.(home), airframe: :plane)
            assert_in_delta distance(Geo.location(approach.x / 1.0e7, approach.y / 1.0e7), home), 400, 1
            run = flown(circuit.(home), id, seen)
            assert {:ok, :done} = run.result
            # The take-off, the waypoint, the loiter and the approach are reported reached (the waypoint back by its DO item's seq, as ArduCopter does); the land item never is.
            assert [1, 2, 3, 6] -- run.reached == [] and 7 not in run.reached, "#{backend}: #{inspect(run.reached)}"
            assert run.view.armed? == false, "#{backend}"
            assert Enum.any?(Vehicles.status_texts(id), fn {_, text} -> text =~ "Auto disarmed" end), "#{backend}"
            # Down where it was sent: in line from its approach, ArduPlane stops within a few metres of the
            # point (5 m; 64 m long without the approach waypoint); the simulator's plane, with no flare, rolls further.
            assert distance(run.view.position, home) < if(backend == :sitl, do: 40, else: 150), "#{backend}"

            # It cannot stand still: a stop leaves it circling where it was, in LOITER.
            loiter = Mission.new("Orbit", [C.home(home), C.take_off(Location.at_height(home, home.h + 60)), C.move_and_loiter_pos(300, 0, 0, 80)])
            held = stopped(loiter, id, 60_000, :loiter)
            assert held.armed? and held.relative_altitude > 20, "#{backend}"
            run
          end)
        end

      assert Enum.any?(sitl.texts, &(&1 =~ "Landing approach start"))
      alike(sim, sitl, "the plane's circuit")
    end
  end

  for {airframe, mav_type, class} <- [{:rover, 10, :ugv}, {:boat, 11, :usv}], SITL.available?(airframe) do
    @airframe airframe
    @mav_type mav_type
    @class class
    test "a #{airframe} drives its mission with no take-off (heights ignored), holds at its timed loiter, and a stop holds it in LOITER; the simulator's alike" do
      route = fn home -> Mission.new("Route", [C.home(home), C.move(60, 0, 0), C.loiter_time(Geo.offset(home, 60, 0, 0), 10), C.move(0, 40, 0), C.speed(3), C.return_home()]) end

      [sim, sitl] =
        for backend <- [:sim, :sitl] do
          on_backend(backend, @airframe, {@class, @airframe, @mav_type}, fn {id, home, seen} ->
            # Nothing in it takes off: a rover or a boat is given it.
            assert Mission.airframes(route.(home)) |> Enum.member?(@airframe)
            run = flown(route.(home), id, seen)
            assert {:ok, :done} = run.result
            # A waypoint followed by a DO item is reported by the DO item's seq (as ArduCopter does).
            assert [1, 2] -- run.reached == [] and (3 in run.reached or 4 in run.reached), "#{backend}: #{inspect(run.reached)}"
            # Its last waypoint reached (ArduRover stays in AUTO, armed, at the end).
            assert distance(run.view.position, home) < 8, "#{backend}"
            assert run.view.mode == :auto and run.view.armed?, "#{backend}"

            far = Mission.new("Away", [C.home(home), C.move(300, 0, 0)])
            held = stopped(far, id, 20_000, :loiter)
            assert held.armed?, "#{backend}"
            assert distance(held.position, home) > 20, "#{backend}"
            run
          end)
        end

      alike(sim, sitl, "#{@airframe}'s route")
    end
  end

  if SITL.available?(:sub) do
    test "a submarine dives to its depths (negative heights), holds its timed loiter, surfaces with its landing, and a stop holds it in POSHOLD; the simulator's alike" do
      dive = fn home ->
        Mission.new("Dive", [
          C.home(home),
          C.move(30, 0, -5),
          C.loiter_time(Geo.offset(home, 30, 0, -5), 10),
          C.move(0, 20, -3),
          C.return_home_and_land()
        ])
      end

      [sim, sitl] =
        for backend <- [:sim, :sitl] do
          on_backend(backend, :sub, {:uuv, :sub, 12}, fn {id, home, seen} ->
            # Depths relative to the surface, frame GLOBAL_RELATIVE_ALT_INT.
            items = Mission.to_items(dive.(home), airframe: :sub)
            assert for(i <- tl(items), do: {i.command, i.frame, Float.round(i.z, 2)}) == [{16, 6, -5.0}, {19, 6, -5.0}, {16, 6, -8.0}, {21, 6, 0.0}]
            run = flown(dive.(home), id, seen)
            assert {:ok, :done} = run.result
            # ArduSub reports its NAV_LAND reached: it goes to its point, surfaces there and stays armed.
            assert 4 in run.reached, "#{backend}"
            assert run.view.position.h > -1.5 and run.view.armed?, "#{backend}"
            assert distance(run.view.position, home) < 5, "#{backend}"

            # Its GCS failsafe waits 5 s of real time, not 5/K (a busy machine's pause is no lost ground station).
            if backend == :sitl, do: assert({:ok, 50.0} = Vehicles.read_param(id, "FS_GCS_TIMEOUT"))

            deep = Mission.new("Deep", [C.home(home), C.move(60, 0, -6)])
            held = stopped(deep, id, 30_000, :poshold)
            assert held.armed? and held.position.h < -0.5, "#{backend}"
            run
          end)
        end

      alike(sim, sitl, "the sub's dive")
    end
  end

  if Enum.all?([:plane, :rover, :sub], &SITL.available?/1) do
    # The killed instances' exits are logged: expected here.
    @tag :capture_log
    test "a plane, a rover and a submarine killed mid-mission: each is lost within its connection timeout, its task fails with the loss, the others fly on" do
      {:ok, fleet} = SITL.start(plane: 1, rover: 1, sub: 1)
      on_exit(fn -> SITL.stop(fleet) end)
      test = self()

      for id <- fleet.sysids, do: Wait.until(fn -> match?({:ok, %{home: %Location{}, position: %Location{}}}, Vehicles.view(id)) end, 3_000)

      by_airframe =
        Map.new(fleet.sysids, fn id ->
          {:ok, view} = Vehicles.view(id)
          {view.airframe, {id, view.home}}
        end)

      long = %{
        plane: fn home -> [C.take_off(Location.at_height(home, home.h + 60), 15), C.move_and_loiter_time(800, 0, 0, 600, 0)] end,
        rover: fn _home -> [C.move(3000, 0, 0)] end,
        sub: fn _home -> [C.move(600, 0, -5)] end
      }

      runs =
        for {airframe, {id, home}} <- by_airframe do
          {:ok, _} = Dolphin.Fleet.pick(Dolphin.Fleet, self(), id: id)
          Vehicles.set_timeout(id, 5_000)
          mission = Mission.new("Long #{airframe}", [C.home(home) | long[airframe].(home)])
          {:ok, run} = Engine.start(Engine.watch(Engine.on(mission, [id]), on_error: fn failure -> send(test, {:handled, failure}) end))
          {airframe, id, home, run}
        end

      # Each under way: the plane climbing out, the rover and the sub 10 m from home.
      for {airframe, id, home, _run} <- runs do
        under_way? = fn
          {:ok, %{armed?: true, relative_altitude: alt}} when airframe == :plane and alt > 15 -> true
          {:ok, %{armed?: true, position: %Location{} = at}} when airframe != :plane -> distance(at, home) > 10
          _ -> false
        end

        Wait.until(fn -> under_way?.(Vehicles.view(id)) end, 6_000, fn -> "#{airframe}: #{inspect(Vehicles.view(id))}" end)
      end

      Vehicles.subscribe(:all)

      for {{airframe, id, _home, run}, n} <- Enum.with_index(runs) do
        lost_from = Dolphin.Clock.now_ms()
        :ok = SITL.crash(fleet, id)
        assert_receive {:dolphin, :vehicles, {:vehicle_lost, ^id}}, Dolphin.Clock.to_real_ms(30_000) + 2_000
        assert Dolphin.Clock.now_ms() - lost_from < 25_000, "#{airframe}"
        assert_receive {:handled, %Dolphin.Engine.Failure{vehicle: ^id, reason: {:vehicle_lost, ^id}}}, 10_000
        assert {:ok, :done} = Engine.await(run, 30_000)

        # The ones not killed yet are still heard, their missions on.
        for {other, other_id, _, other_run} <- Enum.drop(runs, n + 1) do
          refute_received {:dolphin, :vehicles, {:vehicle_lost, ^other_id}}, "#{other} lost with the #{airframe}"
          refute_received {Dolphin.Engine, ^other_run, _}, "#{other}'s task ended with the #{airframe}"
          assert {:ok, %{armed?: true}} = Vehicles.view(other_id)
        end
      end
    end
  end

  if SITL.available?(:rover) and SITL.available?(:sub) do
    @tag :tmp_dir
    test "mix dolphin.run --sitl rover:1,sub:1: a script picks the submarine by its airframe, and the pre-flight check refuses a take-off on it", %{tmp_dir: dir} do
      script = fn name, body -> Path.join(dir, name) |> tap(&File.write!(&1, "use Dolphin.Script\n" <> body)) end

      run = fn argv ->
        {:ok, out} = StringIO.open("")
        {:ok, err} = StringIO.open("")
        code = Mix.Tasks.Dolphin.Run.main(argv, out: out, err: err)
        {code, elem(StringIO.contents(out), 1), elem(StringIO.contents(err), 1)}
      end

      pick = script.("pick.exs", "v = pick(airframe: :sub, timeout: seconds(60))\nmessage(\"the sub is \#{inspect(v)}\")\nrelease(v)\n")
      assert {0, out, ""} = run.([pick, "--sitl", "rover:1,sub:1", "--speedup", "#{@speedup}", "--no-tlog"])
      assert out =~ "2 SITL instance(s) (1 rover, 1 sub), vehicles 1, 2"
      assert out =~ "vehicle 2 discovered (uuv sub)"
      assert out =~ "message: the sub is #Vehicles<[2]>"

      fly = script.("up.exs", "v = pick(airframe: :sub, timeout: seconds(60))\nexecute %{v => mission(\"Up\", do: take_off(location(40.44, -7.37, 20)))}\n")
      assert {1, out, _} = run.([fly, "--sitl", "rover:1,sub:1", "--speedup", "#{@speedup}", "--no-tlog"])
      assert out =~ "no vehicle matches airframe [:copter, :plane, :quadplane]"
      assert out =~ "the vehicles at hand: 2 (uuv sub [:camera])"
      assert out =~ "the pre-flight check found errors: nothing flies"
    end
  end
end
