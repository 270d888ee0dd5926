defmodule Dolphin.Mission.PlatformTest do
  # Missions as engine tasks flown by simulated copters over UDP on 127.0.0.1,
  # in a Dolphin.Instance of the test's own (vehicles, fleet, clock): async.
  use ExUnit.Case, async: true

  alias Dolphin.{Clock, Engine, Mission, Sim, Events, Vehicles}
  alias Dolphin.Mission.Command, as: C
  alias Dolphin.Test.Wait

  @speedup 50

  setup do
    Dolphin.Test.Instance.start!()
    Dolphin.Fleet.set_source({Dolphin.Fleet.MAVLinkSource, nil})
    %{port: Dolphin.Test.GroundStation.open()}
  end

  defp start_fleet(port, opts) do
    {:ok, ids} = Sim.start(Keyword.merge([gcs: port, speedup: @speedup, ekf_ready_ms: 20_000], opts))
    Wait.until(fn -> Enum.all?(ids, &match?({:ok, %{home: %{}}}, Vehicles.state(&1))) end, 1_500, fn -> "homes of #{inspect(ids)}" end)

    # Missions run on picked vehicles.
    for id <- ids, do: {:ok, _} = Dolphin.Fleet.pick(Dolphin.Instance.names().fleet, self(), id: id)

    for id <- ids do
      {:ok, %{home: h}} = Vehicles.state(id)
      {id, Dolphin.Geo.location(h.lat, h.lon, h.alt)}
    end
  end

  defp out_and_back(home) do
    Mission.new("out and back")
    |> Mission.add(C.home(home))
    |> Mission.add(C.take_off(%{home | h: home.h + 20}))
    |> Mission.add(C.move(80, 0, 0))
    |> Mission.add(C.return_home_and_land())
  end

  test "a mission is uploaded, verified, flown and completes when the vehicle has landed and disarmed", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1)
    Events.subscribe()

    assert {:ok, :done} = Engine.run(Engine.on(out_and_back(home), [1]))

    # Retransmissions are counted, not forbidden: at this speed-up a loaded
    # machine's pause outlasts a retry timer even on a clean link.
    assert_received {:dolphin, :events, %{event: :mission_uploaded, vehicle: 1, name: "out and back", items: 4, retransmissions: r}} when is_integer(r)
    {:ok, st} = Vehicles.state(1)
    refute st.armed
    # EXTENDED_SYS_STATE comes once a second (of clock time).
    Wait.until(fn -> match?({:ok, %{landed: :on_ground}}, Vehicles.state(1)) end)
    {:ok, info} = Sim.info(1)
    assert Dolphin.Geo.distance(Dolphin.Geo.location(info.position.lat, info.position.lon), home) < 3
    # Progress reached the engine: one event per item reached. The final
    # NAV_LAND is never reported reached (as on ArduCopter): the mission was
    # done by landing and disarming with it current.
    progress = for {:dolphin, :events, %{event: :task_progress, progress: p}} <- flush(), do: p
    assert progress |> Enum.map(& &1.reached) |> Enum.uniq() |> Enum.reject(&is_nil/1) |> Enum.take(-2) == [1, 2]
    assert %{current: 3, total: 3} = List.last(progress)
  end

  test "the progress of a mission starts from nothing: the previous mission's items reached are not its own", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1)
    first = Mission.new("first") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 20})) |> Mission.add(C.move(20, 0, 0)) |> Mission.add(C.move_and_loiter_time(0, 20, 0, 2))
    assert {:ok, :done} = Engine.run(Engine.on(first, [1]))
    assert {:ok, %{mission: %{reached: 3}}} = Vehicles.state(1)
    # An upload forgets the previous mission's progress at once (what the
    # vehicle says of the new one may already be in: its MISSION_CURRENT seq 0).
    :ok = Vehicles.upload_mission(1, Mission.to_items(out_and_back(home)))
    assert {:ok, %{mission: %{reached: nil, current: current}}} = Vehicles.state(1)
    assert current in [nil, 0]

    Events.subscribe()
    assert {:ok, :done} = Engine.run(Engine.on(out_and_back(home), [1]))
    reached = for {:dolphin, :events, %{event: :task_progress, progress: p}} <- flush(), do: p.reached
    # The take-off (the vehicle is already up) is item 1 reached; 3 never came from the previous mission.
    assert [1, 2] == reached |> Enum.reject(&is_nil/1) |> Enum.dedup()
  end

  test "a mission flies to its end over a link that loses, duplicates and reorders datagrams", %{port: port} do
    [{3, home}] = start_fleet(port, sysids: [3])
    :ok = Sim.set_faults(3, loss: 0.2, duplicate: 0.05, reorder: 0.05)
    assert {:ok, :done} = Engine.run(Engine.on(out_and_back(home), [3]))
    {:ok, info} = Sim.info(3)
    refute info.armed
    assert Dolphin.Geo.distance(Dolphin.Geo.location(info.position.lat, info.position.lon), home) < 3
  end

  test "stopped by until, the vehicle holds position in BRAKE and is free for the next mission", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1)

    endless =
      Mission.new("endless loiter")
      |> Mission.add(C.home(home))
      |> Mission.add(C.take_off(%{home | h: home.h + 15}))
      |> Mission.add(C.move_and_loiter_pos(40, 0, 0, 10))

    reached_loiter = fn -> match?({:ok, %{mission: %{current: 2}, mode: :auto}}, Vehicles.state(1)) end
    stopped_at = fn -> Clock.now_ms() end
    _ = stopped_at

    assert {:ok, :done} = Engine.run(Engine.on(Engine.until(endless, reached_loiter), [1]))
    # Held (the heartbeat shows it within a second of clock time).
    Wait.until(fn -> match?({:ok, %{mode: :brake, armed: true}}, Vehicles.state(1)) end)
    {:ok, a} = Sim.info(1)
    Clock.sleep(10_000)
    {:ok, b} = Sim.info(1)
    assert b.mode == :brake
    assert Dolphin.Geo.distance(Dolphin.Geo.location(a.position.lat, a.position.lon), Dolphin.Geo.location(b.position.lat, b.position.lon)) < 8
    assert_in_delta b.position.relative_alt, a.position.relative_alt, 1.0

    # The next mission takes the vehicle from where it holds, home to land.
    back = Mission.new("back") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 15})) |> Mission.add(C.return_home_and_land())
    assert {:ok, :done} = Engine.run(Engine.on(back, [1]))
    {:ok, st} = Vehicles.state(1)
    refute st.armed
  end

  test "a vehicle still booting (which refuses uploads with NO_SPACE, as ArduCopter does) is waited for", %{port: port} do
    {:ok, [5]} = Sim.start(sysids: [5], gcs: port, speedup: @speedup, boot_ms: 20_000, ekf_ready_ms: 25_000)
    Wait.until(fn -> match?({:ok, %{system_status: 1}}, Vehicles.state(5)) end, 200)
    {:ok, _} = Dolphin.Fleet.pick(Dolphin.Instance.names().fleet, self(), id: 5)
    home = Dolphin.Geo.location(40.444233, -7.375234, 820)
    assert {:ok, :done} = Engine.run(Engine.on(out_and_back(home), [5]))
  end

  test "arming refused for longer than the bound fails the task with the autopilot's reason", %{port: port} do
    {:ok, [4]} = Sim.start(sysids: [4], gcs: port, speedup: @speedup, ekf_ready_ms: 3_600_000)
    Wait.until(fn -> match?({:ok, _}, Vehicles.state(4)) end)
    {:ok, _} = Dolphin.Fleet.pick(Dolphin.Instance.names().fleet, self(), id: 4)
    home = Dolphin.Geo.location(40.444233, -7.375234, 820)
    mission = out_and_back(home)

    {:ok, run} = Engine.start(Engine.on(mission, [4]), [])
    assert {:error, failure} = Engine.await(run, 30_000)
    message = Exception.message(Dolphin.Engine.TaskError.exception(failure: failure))
    assert message =~ "arming refused for 120 s"
    assert message =~ "Need Position Estimate"
  end

  test "a vehicle that leaves AUTO (a battery failsafe) fails its mission with the reason", %{port: port} do
    [{2, home}] = start_fleet(port, sysids: [2], battery_failsafe: :rtl, battery: 0.26)
    long = Mission.new("long") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 20})) |> Mission.add(C.move_and_loiter_time(0, 0, 0, 600))
    assert {:error, failure} = Engine.run(Engine.on(long, [2]))
    message = Exception.message(Dolphin.Engine.TaskError.exception(failure: failure))
    assert message =~ "left AUTO for RTL"
    # The failsafe's RTL is left alone: the vehicle comes home.
    Clock.sleep(5_000)
    assert {:ok, %{mode: :rtl}} = Sim.info(2)
  end

  test "a vehicle armed for its take-off that does not climb fails the task with the reason, in bounded clock time, and is held", %{port: port} do
    # Motors that cannot lift it: armed, in AUTO, spooled up, on the ground for ever.
    [{7, home}] = start_fleet(port, sysids: [7], climb_speed: 0.0)
    {:ok, run} = Engine.start(Engine.on(out_and_back(home), [7]), [])
    started = Clock.now_ms()
    # At most the bound (60 s of clock, never under 15 s of real time) and
    # the telemetry's second after MISSION_START; this test's own wait is a backstop.
    bound = max(180_000, 15_000 * @speedup + 60_000)
    assert {:error, failure} = Engine.await(run, Clock.to_real_ms(bound) + 10_000)
    assert Clock.now_ms() - started < bound
    message = Exception.message(Dolphin.Engine.TaskError.exception(failure: failure))
    assert message =~ "vehicle 7 has been armed on the ground for 60 s of the mission (at item 1 of 3, NAV_TAKEOFF): its take-off does not climb"
    # Left holding, not flying on (the hold follows the report).
    Dolphin.Test.Wait.until(fn -> match?({:ok, %{mode: m, armed: a}} when m in [:brake, :guided] or not a, Sim.info(7)) end, 30_000, fn -> "vehicle 7 held: #{inspect(Sim.info(7))}" end)
  end

  # The executor's exit with its parent's :killed is logged as an error: expected here.
  @tag :capture_log
  test "the engine's leaf killed: the mission's process makes the vehicle hold", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1)
    test = self()
    instance = Dolphin.Instance.current()

    leaf =
      spawn(fn ->
        Dolphin.Instance.put(instance)
        # A loiter of an hour: in the air in AUTO however slowly this test looks.
        hover = Mission.new("hover") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 20})) |> Mission.add(C.move_and_loiter_time(0, 0, 0, 3_600))
        {:ok, pid} = Dolphin.Mission.Executor.start_link(hover, 1, owner: self())
        send(test, {:executor, pid})
        Process.sleep(:infinity)
      end)

    assert_receive {:executor, executor}, 30_000
    Wait.until(fn -> match?({:ok, %{mode: :auto, position: %{relative_alt: alt}}} when alt > 5, Sim.info(1)) end)
    ref = Process.monitor(executor)
    Process.exit(leaf, :kill)
    assert_receive {:DOWN, ^ref, :process, _, _}, 10_000
    assert {:ok, %{mode: :brake, armed: true}} = Sim.info(1)
  end

  test "the mission's process is a :gen_statem through its steps, open to :sys; stopped in flight, the vehicle holds", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1)
    hover = Mission.new("hover") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 20})) |> Mission.add(C.move_and_loiter_time(0, 0, 0, 3_600))
    {:ok, pid} = Dolphin.Mission.Executor.start_link(hover, 1, owner: self())
    # Every change of step, as :sys reports it.
    test = self()
    :ok = :sys.install(pid, {fn acc, event, _ -> match?({:consume, _, from, to} when from != to, event) and send(test, {:step, elem(event, 3)}) && acc end, nil})

    Wait.until(fn -> match?({:flying, %{vehicle: 1}}, :sys.get_state(pid)) end)
    steps = steps()
    # The steps it took after :sys was installed, in order.
    assert Enum.drop_while([:hold, :clear, :upload, :verify, :guided, :arm, :start, :flying], &(&1 not in steps)) == steps

    Wait.until(fn -> match?({:ok, %{mode: :auto, position: %{relative_alt: alt}}} when alt > 5, Sim.info(1)) end)
    assert_receive {:dolphin_platform, ^pid, {:progress, %{}}}, 30_000
    ref = Process.monitor(pid)
    assert :ok = Dolphin.Mission.Executor.stop(pid, :operator)
    assert_receive {:DOWN, ^ref, :process, ^pid, :normal}
    assert {:ok, %{mode: :brake, armed: true}} = Sim.info(1)
  end

  # ArduCopter disarms a copter that stands armed on the ground in BRAKE
  # (docs/ardupilot.md): held by the separation monitor before it left the
  # ground, the mission waits, and once let go arms and starts again.
  # Vehicle 1's mission (out and back), held the moment it first flies: its
  # motors spool up for 50 s of clock time, 5 s of real time at 10x, and the
  # hold, sent as MISSION_START is accepted, comes during it. `opts` are the
  # vehicle's settings.
  defp held_at_spool_up(port, opts), do: spooling_up(port, opts, Dolphin.Test.SeparationHold.at_first_flight())

  # Vehicle 1's mission with a take-off whose spool-up lasts 50 s of clock
  # time; `executor_opts` beside its owner.
  defp spooling_up(port, opts, executor_opts) do
    [{1, home}] = start_fleet(port, [count: 1, spool_up_ms: 50_000, speedup: 10] ++ opts)
    Events.subscribe()
    {:ok, pid} = Dolphin.Mission.Executor.start_link(out_and_back(home), 1, [owner: self()] ++ executor_opts)
    {home, pid}
  end

  # Held in BRAKE, armed, on the ground, by an autopilot that would wait ten minutes to disarm it.
  defp held_armed_in_brake(port) do
    {home, pid} = held_at_spool_up(port, disarm_delay_ms: 600_000)
    Wait.until(fn -> match?({:ok, %{armed: true, mode: :brake, landed: :on_ground}}, Sim.info(1)) end, 1_500, fn -> "vehicle 1 held in BRAKE: " <> where_held(pid) end)
    {home, pid}
  end

  # Where vehicle 1 and `pid`'s mission are, for a wait that timed out: the
  # simulator's truth, the mission's step and hold, and its end if it ended.
  defp where_held(pid) do
    ending =
      receive do
        {:dolphin_platform, ^pid, {:failed, f}} -> "failed: " <> inspect(f, limit: 12)
        {:dolphin_platform, ^pid, :done} -> "done (never held?)"
      after
        0 -> "none yet"
      end

    truth = with {:ok, info} <- Sim.info(1), do: Map.take(info, [:armed, :mode, :landed, :current, :position])
    step = if Process.alive?(pid), do: with({step, data} <- :sys.get_state(pid), do: {step, Map.take(data, [:separation, :held_on_ground, :rearms, :leaving])}), else: :ended
    "vehicle 1: #{inspect(truth)}; the mission: #{inspect(step)}; its end: #{ending}"
  end

  # The mission done, the vehicle disarmed at home.
  defp done_at_home(pid, home) do
    assert_receive {:dolphin_platform, ^pid, :done}, 120_000
    {:ok, info} = Sim.info(1)
    refute info.armed
    assert Dolphin.Geo.distance(Dolphin.Geo.location(info.position.lat, info.position.lon), home) < 3
  end

  @tag timeout: 300_000
  test "held before it left the ground and disarmed there by the autopilot, a copter is armed and started again once let go", %{port: port} do
    {home, pid} = held_at_spool_up(port, [])
    Wait.until(fn -> match?({:ok, %{armed: false, mode: :brake, landed: :on_ground}}, Sim.info(1)) end, 1_500, fn -> "vehicle 1 disarmed in BRAKE: " <> where_held(pid) end)
    # Its views come at 1 Hz of clock time: a few more, and the mission still waits.
    Clock.sleep(3_000)
    refute_received {:dolphin_platform, ^pid, {:failed, _}}
    assert {:flying, _} = :sys.get_state(pid)

    Dolphin.Test.SeparationHold.let_go(pid)
    done_at_home(pid, home)
    assert_received {:dolphin, :events, %{event: :mission_restarted, vehicle: 1, name: "out and back", reason: :disarmed_while_held}}
  end

  @tag timeout: 300_000
  test "held during its spool-up and let go before the autopilot disarms it, a copter takes off again in AUTO: no restart", %{port: port} do
    {home, pid} = held_armed_in_brake(port)
    Dolphin.Test.SeparationHold.let_go(pid)
    done_at_home(pid, home)
    refute_received {:dolphin, :events, %{event: :mission_restarted}}
  end

  # Let go as DISARM_DELAY ran out (held 9.9 s in search_and_signal.exs), the
  # copter was disarmed in AUTO before its motors spooled up again: here
  # the disarm comes in AUTO, after the resume, by command.
  @tag timeout: 300_000
  test "held before it left the ground, let go, then disarmed in AUTO before it left the ground: armed and started again", %{port: port} do
    {home, pid} = held_armed_in_brake(port)
    Dolphin.Test.SeparationHold.let_go(pid)
    # Back in AUTO as the executor sees it (its hold over), still spooling up.
    Wait.until(fn -> match?({:flying, %{separation: nil}}, :sys.get_state(pid)) and match?({:ok, %{mode: :auto}}, Vehicles.view(1)) end)
    {:ok, _} = Vehicles.disarm(1)

    done_at_home(pid, home)
    assert_received {:dolphin, :events, %{event: :mission_restarted, vehicle: 1, reason: :disarmed_while_held}}
  end

  # Over 30 % loss on a loaded host (the lossy-link example, vehicle 2):
  # DISARM_DELAY ran out in GUIDED before MISSION_START came, the heartbeat
  # saying so was lost, and the mission's ACTIVE came with the armed bit of
  # the one before: seen armed in its mission, then disarmed in AUTO, on the
  # ground. Here the disarm comes in AUTO during the spool-up, by command.
  @tag timeout: 300_000
  test "seen armed in its mission, disarmed in AUTO before it left the ground: armed and started again", %{port: port} do
    {home, pid} = spooling_up(port, [], [])

    Wait.until(
      fn -> match?({:flying, %{flight: %{armed_seen: true, airborne_seen: false}}}, :sys.get_state(pid)) and match?({:ok, %{armed: true, mode: :auto, landed: :takeoff}}, Sim.info(1)) end,
      1_500,
      fn -> "vehicle 1 seen armed in its mission, spooling up: " <> where_held(pid) end
    )

    {:ok, _} = Vehicles.disarm(1)
    done_at_home(pid, home)
    assert_received {:dolphin, :events, %{event: :mission_restarted, vehicle: 1, reason: :disarmed_before_start}}
    refute_received {:dolphin_platform, ^pid, {:failed, _}}
  end

  # ArduPilot drops a COMMAND_ACK when its link has no room: MISSION_START
  # taken, never answered, the vehicle flies the mission in AUTO.
  test "a MISSION_START taken but never acknowledged: the mission is followed as started, and done", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1, unacked_commands: [300])
    assert {:ok, :done} = Engine.run(Engine.on(out_and_back(home), [1]))
    {:ok, info} = Sim.info(1)
    refute info.armed
    assert Dolphin.Geo.distance(Dolphin.Geo.location(info.position.lat, info.position.lon), home) < 3
  end

  # The vehicle said it had no upload under way just after it asked for the
  # last item, so the protocol took its ACCEPTED for lost (unconfirmed); but
  # it had given up, and holds nothing. The read-back shows it: uploaded again.
  test "an unconfirmed upload the vehicle does not hold is uploaded again, then flown", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1, gives_up_uploads: 1)
    Events.subscribe()
    assert {:ok, :done} = Engine.run(Engine.on(out_and_back(home), [1]))
    uploads = for {:dolphin, :events, %{event: :mission_uploaded, vehicle: 1}} <- flush(), do: :uploaded
    assert length(uploads) == 2
  end

  test "stopped right after MISSION_START, before telemetry shows it, the vehicle still holds", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1)
    {:ok, run} = Engine.start(Engine.on(out_and_back(home), [1]))
    # As soon as the vehicle itself is in AUTO (the ground station's view lags up to a second).
    Wait.until(fn -> match?({:ok, %{mode: :auto}}, Sim.info(1)) end)
    :ok = Engine.stop(run)
    assert {:ok, :stopped} = Engine.await(run, 30_000)
    {:ok, info} = Sim.info(1)
    assert info.mode in [:brake, :guided] or not info.armed
  end

  test "a mission the vehicle completes at once (already at height, then a photo) is done", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1, camera: true)
    up = Mission.new("up") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 20})) |> Mission.add(C.move_and_loiter_pos(0, 0, 0, 10))
    reached_loiter = fn -> match?({:ok, %{mission: %{current: 2}, mode: :auto}}, Vehicles.state(1)) end
    assert {:ok, :done} = Engine.run(Engine.on(Engine.until(up, reached_loiter), [1]))

    photo = Mission.new("photo") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 20})) |> Mission.add(C.capture_photo())
    assert {:ok, :done} = Engine.run(Engine.on(photo, [1]))
    assert {:ok, %{photos: 1}} = Sim.info(1)
  end

  # A plan's return to launch (MAV_CMD_NAV_RETURN_TO_LAUNCH: QGroundControl ends its plans with one) lands at the vehicle's home.
  test "a mission that only returns to launch is done at once on a copter standing at its home; elsewhere it is refused", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1)
    Events.subscribe()
    home_again = Mission.new("home again") |> Mission.add(C.home(home)) |> Mission.add(C.item(:mav_cmd_nav_return_to_launch))
    Wait.until(fn -> match?({:ok, %{landed: :on_ground}}, Vehicles.state(1)) end)

    assert {:ok, :done} = Engine.run(Engine.on(home_again, [1]))
    # Nothing was sent to fly: no upload, no arming.
    refute Enum.any?(flush(), &match?({:dolphin, :events, %{event: :mission_uploaded}}, &1))
    assert {:ok, %{armed: false}} = Vehicles.state(1)

    # Landed 80 m away, the same mission has nothing it can fly.
    away = Mission.new("away") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 20})) |> Mission.add(C.landing_point(Dolphin.Geo.offset(home, 80, 0)))
    assert {:ok, :done} = Engine.run(Engine.on(away, [1]))
    assert {:error, failure} = Engine.run(Engine.on(home_again, [1]))
    assert Exception.message(Dolphin.Engine.TaskError.exception(failure: failure)) =~ "on the ground and the mission has no take-off"
  end

  test "a copter that disarms on the ground before MISSION_START reaches it is armed and started again, and flies once the start comes in time", %{port: port} do
    # Every datagram takes 0.5 s of the vehicle's time each way, and it
    # disarms 0.7 s after its arm (DISARM_DELAY): the start, sent when the
    # arm's answer comes, reaches it 1 s after the arm, too late, as
    # ArduCopter's 10 s can pass on a slow, lossy link; the task would wait in
    # AUTO, disarmed, for ever. At 10x: with the link quick again, the start
    # must come within those 0.7 s of clock, 70 ms of real time (at 50x, and
    # 0.2 s, it was 4 ms, which a loaded host missed four times in a row).
    [{1, home}] = start_fleet(port, count: 1, disarm_delay_ms: 700, speedup: 10)
    :ok = Sim.set_faults(1, latency: 500)
    test = self()
    instance = Dolphin.Instance.current()

    # The link is quick again when the executor sets GUIDED the second time.
    spawn_link(fn ->
      Dolphin.Instance.put(instance)
      Events.subscribe()
      send(test, :watching)
      receive do: ({:dolphin, :events, %{event: :mode_changed, vehicle: 1, mode: :guided}} -> :ok)
      receive do: ({:dolphin, :events, %{event: :mode_changed, vehicle: 1, mode: :auto}} -> :ok)
      :ok = Sim.set_faults(1, latency: 0)
    end)

    # (Subscribed: spawned on a busy host, that can take longer than
    # assert_receive's default 100 ms.)
    assert_receive :watching, 5_000
    assert {:ok, :done} = Engine.run(Engine.on(out_and_back(home), [1]))
    {:ok, info} = Sim.info(1)
    assert Dolphin.Geo.distance(Dolphin.Geo.location(info.position.lat, info.position.lon), home) < 3
  end

  test "a copter just landed at home, still armed, has nothing to fly of a mission that only comes back and lands: done", %{port: port} do
    # ArduCopter refuses AUTO on the ground without a take-off, armed or not
    # ("Auto: Missing Takeoff Cmd"): a mission stopped in its landing leaves
    # a copter so, and the next one brings it home.
    [{1, home}] = start_fleet(port, count: 1, disarm_delay_ms: 600_000)
    :ok = Dolphin.Vehicles.Manoeuvres.guided(1, within: 60_000)
    {:ok, _} = Dolphin.Vehicles.arm(1)
    Wait.until(fn -> match?({:ok, %{armed?: true, landed: :on_ground}}, Vehicles.view(1)) end)
    back = Mission.new("Home") |> Mission.add(C.home(home)) |> Mission.add(C.return_home_and_land())

    assert {:ok, :done} = Engine.run(Engine.on(back, [1]))
    {:ok, info} = Sim.info(1)
    assert info.mode == :guided and info.armed
  end

  test "a boat that disarms itself in the instant it is armed (never seen armed) is armed and started again, and drives its mission", %{port: port} do
    # As ArduRover SITL once did on a loaded host: the mission would have
    # waited in AUTO, disarmed, for ever.
    [{1, home}] = start_fleet(port, count: 1, airframe: :boat, disarms_at_arming: 2)
    drive = Mission.new("drive") |> Mission.add(C.home(home)) |> Mission.add(C.move(60, 0, 0))

    assert {:ok, :done} = Engine.run(Engine.on(drive, [1]))
    {:ok, info} = Sim.info(1)
    assert_in_delta Dolphin.Geo.distance(Dolphin.Geo.location(info.position.lat, info.position.lon), home), 60, 5
    # Armed three times: twice disarmed at once, then driven.
    assert info.disarms_at_arming == 0
  end

  test "a boat that disarms itself at every arm fails its mission, saying so, instead of waiting for ever", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1, airframe: :boat, disarms_at_arming: 100)
    drive = Mission.new("drive") |> Mission.add(C.home(home)) |> Mission.add(C.move(60, 0, 0))

    assert {:error, failure} = Engine.run(Engine.on(drive, [1]))
    assert Exception.message(Dolphin.Engine.TaskError.exception(failure: failure)) =~ "vehicle 1 disarmed before its mission began, 4 time(s)"
  end

  test "the second of two missions reports its own progress from the start, and its take-off is an item reached", %{port: port} do
    [{1, home}] = start_fleet(port, count: 1)
    # The first mission's last item reached is its take-off, item 1: the second one's take-off has the same number.
    up = Mission.new("up") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 20})) |> Mission.add(C.move_and_loiter_pos(0, 0, 0, 10))
    reached_loiter = fn -> match?({:ok, %{mission: %{current: 2, reached: 1}, mode: :auto}}, Vehicles.state(1)) end
    assert {:ok, :done} = Engine.run(Engine.on(Engine.until(up, reached_loiter), [1]))
    Events.subscribe()
    flush()

    back = Mission.new("Return to base") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 30})) |> Mission.add(C.return_home_and_land())
    assert {:ok, :done} = Engine.run(Engine.on(back, [1]))
    events = for {:dolphin, :events, e} <- flush(), do: e

    [first | _] = progress = for %{event: :task_progress, progress: p} <- events, do: p
    assert first.reached in [nil, 0], "the first progress of \"Return to base\" is #{inspect(first)}"
    # Its final NAV_LAND is never reported reached (as on ArduCopter).
    assert Enum.uniq(for(p <- progress, p.reached, do: p.reached)) == [1]
    assert %{seq: 1} = Enum.find(events, &match?(%{event: :mission_item_reached, vehicle: 1}, &1))
  end

  test "requirements: a mission that takes photos needs a camera, one that takes off something that flies, a raw one any airframe" do
    home = Dolphin.Geo.location(40.444233, -7.375234, 820)
    photo = Mission.new("photo") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(home)) |> Mission.add(C.capture_photo())
    assert Dolphin.Mission.Platform.requirements(photo) == %{airframe: [:copter, :plane, :quadplane], payloads: [:camera]}
    assert Dolphin.Mission.Platform.requirements(Mission.new("x", [C.move(10, 0, 0)])) == %{airframe: [:copter, :plane, :quadplane, :rover, :boat, :sub], payloads: []}
    assert Dolphin.Mission.Platform.requirements(Mission.new("raw", [C.item(16, position: home)])) == %{airframe: nil, payloads: []}
  end

  defp steps do
    receive do
      {:step, s} -> [s | steps()]
    after
      0 -> []
    end
  end

  defp flush do
    receive do
      m -> [m | flush()]
    after
      0 -> []
    end
  end
end
