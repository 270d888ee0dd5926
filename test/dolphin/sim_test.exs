defmodule Dolphin.SimTest do
  # Simulated vehicles against the real ground-station stack (link, vehicles,
  # command and mission protocols), over UDP on 127.0.0.1, in a
  # Dolphin.Instance of the test's own (vehicles, clock): async.
  use ExUnit.Case, async: true

  alias Dolphin.{Clock, Sim, Vehicles}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Test.Wait

  doctest Dolphin.Sim.Error

  setup do
    Dolphin.Test.Instance.start!()
    %{port: Dolphin.Test.GroundStation.open()}
  end

  # What the ground station knows (a blank state before discovery).
  defp state(sysid) do
    case Vehicles.state(sysid) do
      {:ok, s} -> s
      {:error, :unknown_vehicle} -> Dolphin.Vehicles.State.new(sysid)
    end
  end

  # Metres between two {lat, lon} (WGS84, Dolphin.Geo).
  defp distance({lat1, lon1}, {lat2, lon2}), do: Dolphin.Geo.distance(Dolphin.Geo.location(lat1, lon1), Dolphin.Geo.location(lat2, lon2))

  # `seconds`: what the wait needs on an idle machine; a loaded one gets at
  # least Wait.until/3's default.
  defp wait(fun, seconds, what), do: Wait.until(fun, max(seconds * 50, 1_500), fn -> what end)

  # The least distance (m) from `point` of the positions vehicle `sysid` reported
  # until it reported mission item `seq` reached (the caller subscribed to
  # `{:vehicle, sysid}` before the mission started).
  defp closest_until_reached(sysid, point, seq, closest \\ :infinity) do
    receive do
      {:dolphin, {:vehicle, ^sysid}, {:view, view}} ->
        closest =
          case view.position do
            %{lat: lat, lon: lon} -> min(closest, distance({lat, lon}, {point.lat, point.lon}))
            nil -> closest
          end

        case view.mission do
          %{reached: reached} when is_integer(reached) and reached >= seq -> closest
          _ -> closest_until_reached(sysid, point, seq, closest)
        end
    after
      60_000 -> flunk("vehicle #{sysid} did not report mission item #{seq} reached; closest to it: #{closest} m")
    end
  end

  defp item(seq, command, {lat, lon, alt}, extra \\ %{}) do
    struct(M.MissionItemInt, Map.merge(%{seq: seq, command: command, frame: 6, x: round(lat * 1.0e7), y: round(lon * 1.0e7), z: alt * 1.0, autocontinue: 1}, extra))
  end

  # Arms in GUIDED, retrying while the autopilot is not ready, as an operator would.
  defp arm(sysid, tries \\ 50) do
    case Vehicles.arm(sysid) do
      {:ok, :accepted} -> :ok
      {:error, _} when tries > 0 -> Clock.sleep(1_000) && arm(sysid, tries - 1)
      {:error, e} -> flunk("arming refused: #{Exception.message(e)}")
    end
  end

  test "vehicles are discovered with distinct ids, homes a few tens of metres apart, and a camera", %{port: port} do
    Vehicles.subscribe(:all)
    {:ok, [1, 2, 3]} = Sim.start(count: 3, gcs: port, speedup: 10, camera: [3], ekf_ready_ms: 1_000)

    for id <- [1, 2, 3], do: assert_receive({:dolphin, :vehicles, {:vehicle_discovered, ^id}}, 3_000)

    homes =
      wait(
        fn ->
          homes = Enum.map([1, 2, 3], &state(&1).home)
          Enum.all?(homes) && homes
        end,
        10,
        "homes reported"
      )

    [a, b, c] = Enum.map(homes, fn h -> {h.lat, h.lon} end)
    assert a != b and b != c
    assert_in_delta distance(a, b), 30, 0.5
    assert_in_delta distance(a, c), 60, 0.5

    assert state(1).type == 2 and state(1).autopilot == :ardupilot
    wait(fn -> MapSet.member?(state(3).components, :camera) end, 5, "a camera component")
    refute MapSet.member?(state(1).components, :camera)

    # Each sends from its own port.
    ports = for id <- [1, 2, 3], do: elem(Sim.info(id), 1).port
    assert length(Enum.uniq(ports)) == 3
  end

  test "a mission uploaded by the ground station is verified, flown and ends landed at home", %{port: port} do
    {:ok, [1]} = Sim.start(count: 1, gcs: port, speedup: 50, ekf_ready_ms: 5_000)
    home = wait(fn -> state(1).home end, 10, "home position")
    north = Dolphin.Sim.Copter.offset(%{lat: home.lat, lon: home.lon, alt: 0}, 80, 0)

    items = [
      item(0, 16, {home.lat, home.lon, 0}),
      item(1, 22, {0, 0, 20}),
      item(2, 16, {north.lat, north.lon, 25}),
      item(3, 20, {0, 0, 0})
    ]

    assert :ok = Vehicles.upload_mission(1, items)
    {:ok, back} = Vehicles.download_mission(1)
    assert length(back) == 4
    assert Enum.map(tl(back), & &1.command) == [22, 16, 20]
    # Frames are normalised on the way back (6 -> 3), as ArduPilot does.
    assert Enum.at(back, 2).frame == 3 and Enum.at(back, 2).x == Enum.at(items, 2).x

    {:ok, :accepted} = Vehicles.set_mode(1, :guided)
    arm(1)
    # The vehicle flies on once it has reached the waypoint: where it is when
    # this process looks depends on the machine's speed, so the check is on the
    # positions it reported, in order, up to its MISSION_ITEM_REACHED.
    Dolphin.PubSub.subscribe({:vehicle, 1})
    {:ok, :accepted} = Vehicles.start_mission(1)

    assert closest_until_reached(1, north, 2) < 3

    wait(
      fn ->
        s = state(1)
        s.mission.state == :complete and not s.armed and s.landed == :on_ground
      end,
      60,
      "mission complete, landed, disarmed"
    )

    s = state(1)
    assert s.mode == :auto
    assert distance({s.position.lat, s.position.lon}, {home.lat, home.lon}) < 3
    assert Enum.any?(s.status_texts, &(&1 == {6, "Disarming motors"}))
  end

  # At 25x, the vehicle's own patience (8 s of clock time) is a third of a
  # second of real time; a loaded host stalls a process for longer than that
  # (CI saw a clear given up as "never answered" over a bad link). An
  # exchange waits at least 5 s of real time before it gives up.
  test "a clear and a command wait out a vehicle whose host stalls past the clock's patience", %{port: port} do
    {:ok, [9]} = Sim.start(sysids: [9], gcs: port, speedup: 25)
    wait(fn -> state(9).autopilot == :ardupilot end, 5, "discovery")
    [{sim, _}] = Registry.lookup(Dolphin.Instance.names().registry, {:sim, 9})

    for exchange <- [fn -> Vehicles.clear_mission(9) end, fn -> Vehicles.set_mode(9, :guided) end] do
      :ok = :sys.suspend(sim)
      task = Task.async(exchange)
      Process.sleep(1_500)
      :ok = :sys.resume(sim)
      assert Task.await(task, 30_000) in [:ok, {:ok, :accepted}]
    end
  end

  test "arming refused before the position estimate, with the autopilot's reason", %{port: port} do
    {:ok, [7]} = Sim.start(sysids: [7], gcs: port, speedup: 5, ekf_ready_ms: 600_000)
    # Modes go by name once a HEARTBEAT said which autopilot it is (the first
    # frame to arrive may be another).
    wait(fn -> state(7).autopilot == :ardupilot end, 5, "discovery")
    {:ok, :accepted} = Vehicles.set_mode(7, :stabilize)
    assert {:error, %Dolphin.CommandError{result: :failed}} = Vehicles.arm(7)
    wait(fn -> {2, "Arm: Need Position Estimate"} in state(7).status_texts end, 5, "the refusal's STATUSTEXT")
  end

  test "modes set by command show in the heartbeat; BRAKE and GUIDED hold, LOITER sinks", %{port: port} do
    {:ok, [1]} = Sim.start(count: 1, gcs: port, speedup: 30, ekf_ready_ms: 1_000)
    wait(fn -> state(1).home end, 10, "home position")
    {:ok, :accepted} = Vehicles.set_mode(1, :guided)
    arm(1)
    {:ok, :accepted} = Vehicles.takeoff(1, 20)

    wait(
      fn ->
        s = state(1)
        s.position && s.position.relative_alt > 19.5
      end,
      30,
      "take-off to 20 m"
    )

    for mode <- [:brake, :guided] do
      {:ok, :accepted} = Vehicles.set_mode(1, mode)
      wait(fn -> state(1).mode == mode end, 5, "mode #{mode}")
      Clock.sleep(5_000)
      assert state(1).position.relative_alt > 19
    end

    {:ok, :accepted} = Vehicles.set_mode(1, :loiter)
    wait(fn -> not state(1).armed end, 60, "LOITER without throttle lands and disarms")
  end

  test "faults: a lossy link still carries a mission; silence loses the vehicle until it returns; a crash loses it", %{port: port} do
    Vehicles.subscribe(:all)
    {:ok, [1, 2]} = Sim.start(count: 2, gcs: port, speedup: 20, ekf_ready_ms: 1_000, seed: 42)
    wait(fn -> state(1).home && state(2).home end, 10, "both ready")
    home = state(1).home

    :ok = Sim.set_faults(1, loss: 0.25, duplicate: 0.1, reorder: 0.1)
    items = [item(0, 16, {home.lat, home.lon, 0}), item(1, 22, {0, 0, 10})] ++ for(s <- 2..20, do: item(s, 16, {home.lat + s * 1.0e-5, home.lon, 10}))
    # A lost final MISSION_ACK is never repeated: the ground station cannot know
    # the outcome then, and says so (:unconfirmed; a mission task reads the
    # mission back); otherwise the vehicle has the mission. Never a wrong one.
    sent = Enum.map(tl(items), & &1.x)

    case Vehicles.upload_mission(1, items) do
      :ok ->
        {:ok, info} = Sim.info(1)
        assert Enum.map(info.mission, & &1.x) == sent

      {:error, %Dolphin.MissionError{result: :unconfirmed}} ->
        {:ok, info} = Sim.info(1)
        assert Enum.map(info.mission, & &1.x) in [[], sent]
    end

    :ok = Sim.set_faults(1, loss: 0, duplicate: 0, reorder: 0)

    Vehicles.set_timeout(2, 3_000)
    :ok = Sim.set_faults(2, silence: true)
    assert_receive {:dolphin, :vehicles, {:vehicle_lost, 2}}, 5_000
    :ok = Sim.set_faults(2, silence: false)
    assert_receive {:dolphin, :vehicles, {:vehicle_reconnected, 2}}, 5_000

    :ok = Sim.crash(2, reboot: true)
    wait(fn -> match?({:ok, %{time_ms: t}} when t < 20_000, Sim.info(2)) end, 5, "vehicle 2 rebooted")

    :ok = Sim.crash(2)
    assert_receive {:dolphin, :vehicles, {:vehicle_lost, 2}}, 5_000
    assert Sim.info(2) == {:error, :unknown_vehicle}
    assert Sim.vehicles() == [1]
  end

  test "actions at a mission item happen right after its report: silenced, low battery, crashed", %{port: port} do
    Vehicles.subscribe(:all)
    {:ok, [1, 2]} = Sim.start(count: 2, gcs: port, speedup: 20, ekf_ready_ms: 1_000)
    wait(fn -> state(1).home && state(2).home end, 10, "both ready")
    for id <- [1, 2], do: Vehicles.set_timeout(id, 3_000)

    # Two actions at one item, in the order given (all lost, then none
    # lost but silent: the second wins); the battery before it.
    :ok = Sim.on_item_reached(1, 1, {:battery, 0.5})
    :ok = Sim.on_item_reached(1, 2, {:faults, loss: 1.0})
    :ok = Sim.on_item_reached(1, 2, {:faults, loss: 0.0, silence: true})
    :ok = Sim.on_item_reached(2, 2, :crash)
    assert {:error, %Sim.Error{message: "bad action :explode at item 3" <> _}} = Sim.on_item_reached(1, 3, :explode)
    assert {:error, %Sim.Error{message: "bad fault :noise" <> _}} = Sim.on_item_reached(1, 3, {:faults, noise: 1})
    assert {:error, :unknown_vehicle} = Sim.on_item_reached(9, 1, :crash)

    for id <- [1, 2] do
      home = state(id).home
      items = [item(0, 16, {home.lat, home.lon, 0}), item(1, 22, {0, 0, 10})] ++ for(s <- 2..5, do: item(s, 16, {home.lat + s * 2.0e-5, home.lon, 10}))
      :ok = Vehicles.upload_mission(id, items)
      {:ok, :accepted} = Vehicles.set_mode(id, :guided)
      arm(id)
      {:ok, :accepted} = Vehicles.start_mission(id)
    end

    # Both reports of item 2 came through; nothing after them.
    assert_receive {:dolphin, :vehicles, {:vehicle_lost, 1}}, 10_000
    assert_receive {:dolphin, :vehicles, {:vehicle_lost, 2}}, 10_000
    assert state(1).mission.reached == 2 and state(2).mission.reached == 2
    # Vehicle 1 flew on, unheard, on half a battery; vehicle 2 is gone.
    {:ok, info} = Sim.info(1)
    assert info.faults.silence and info.faults.loss == 0.0 and info.battery <= 0.5
    assert Sim.info(2) == {:error, :unknown_vehicle}
    assert Sim.vehicles() == [1]
  end

  test "bad options are refused with what was wrong" do
    assert {:error, %Sim.Error{reason: :bad_option, message: "the simulator needs :gcs" <> _}} = Sim.start(count: 1)
    assert {:error, %Sim.Error{message: "bad :count 0" <> _}} = Sim.start(count: 0, gcs: 14_550)
    assert {:error, %Sim.Error{message: "the simulator sends to a ground station" <> _}} = Sim.start(gcs: "udpin:0.0.0.0:14550")
    assert {:error, %Sim.Error{message: "system ids 250..259" <> _}} = Sim.start(count: 10, first_sysid: 250, gcs: 14_550)
  end

  test "values a vehicle could not report, or that mean nothing, are refused before any vehicle starts" do
    refused = [
      {[home: %{lat: 200, lon: 0, alt: 0}], "bad home: the latitude 200 is not within -90..90"},
      {[home: %{lat: 250, lon: 400, alt: 0}], "bad home: the latitude 250 is not within -90..90"},
      {[home: {40, 400, 0}], "bad home: the longitude 400 is not within -180..180"},
      {[home: {40, -7, 2.0e7}], "bad home: the altitude 2.0e7 m is not within -1000..10000"},
      {[homes: [{0, 0, 0}, {91, 0, 0}], sysids: [77, 78]], "bad home: the latitude 91 is not within -90..90"},
      {[charger: {0, 181, 0}], "bad :charger: the longitude 181 is not within -180..180"},
      {[home: {89.9999, 0, 0}, sysids: Enum.to_list(101..112)], "bad home: vehicles 30 m apart around 89.9999, 0.0 would stand at"},
      {[speedup: 1.0e9], "bad :speedup: a speed-up is a number from 0.01 to 1000"},
      {[speedup: 0.0], "bad :speedup: a speed-up is a number from 0.01 to 1000"},
      {[battery: 5.0], "bad :battery 5.0: a fraction of a full pack, from 0 to 1"},
      {[hover_current: 1_000], "bad :hover_current 1000: amperes, more than 0 and at most 200"},
      {[cruise_speed: 0], "bad :cruise_speed 0: m/s, more than 0 and at most 50"},
      {[ekf_ready_ms: -1], "bad :ekf_ready_ms -1: milliseconds, 0 or more"},
      {[battery_failsafe: :explode], "bad :battery_failsafe :explode: one of :none, :rtl, :land"},
      {[gcs_sysid: 0], "bad :gcs_sysid 0: a system id from 1 to 255"},
      {[unacked_commands: [300, -1]], "bad :unacked_commands [300, -1]: a list of MAV_CMD numbers (0 to 65535)"},
      {[spool_up_ms: -5], "bad :spool_up_ms -5: milliseconds, 0 or more"},
      {[gives_up_uploads: 1.5], "bad :gives_up_uploads 1.5: a number of uploads from 0 to 100"},
      {[faults: %{loss: 5}], "bad fault :loss: 5"},
      {[faults: 5], "bad :faults 5: a map or keyword list"}
    ]

    for {opts, message} <- refused do
      result = Sim.start(opts ++ [gcs: 14_550, sysids: [77]])
      Sim.stop()
      assert {:error, %Sim.Error{reason: :bad_option, message: got}} = result, "#{inspect(opts)}: #{inspect(result)}"
      assert String.starts_with?(got, message), "#{inspect(opts)}: #{got}"
    end

    assert Sim.vehicles() == []
    # The speed-up of a refused start is not taken.
    assert Clock.speedup() == 1
  end

  test "a message with a value it cannot carry is not sent, and said once; the vehicle goes on" do
    {:ok, socket} = :gen_udp.open(0, [:binary, active: true, ip: {127, 0, 0, 1}])
    {:ok, port} = :inet.port(socket)
    on_exit(fn -> :gen_udp.close(socket) end)

    log =
      ExUnit.CaptureLog.capture_log(fn ->
        # Past Dolphin.Sim.start/1's checks: a home HOME_POSITION cannot carry
        # (degE7 beyond int32), sent as soon as the position estimate is ready.
        home = %{lat: 250.0, lon: 40.0, alt: 0.0}
        pid = start_supervised!({Dolphin.Sim.Vehicle, sysid: 78, gcs: {{127, 0, 0, 1}, port}, home: home, config: %{ekf_ready_ms: 0}, register: false})
        Process.put(:vehicle, pid)
        Wait.until(fn -> match?({:ok, %{home: %{}}}, GenServer.call(pid, :info)) end)
        {:ok, %{port: vehicle_port}} = GenServer.call(pid, :info)

        for _ <- 1..2 do
          request = %M.CommandLong{target_system: 78, target_component: 1, command: 512, param1: 242.0, param2: 0.0, param3: 0.0, param4: 0.0, param5: 0.0, param6: 0.0, param7: 0.0}
          :ok = :gen_udp.send(socket, {127, 0, 0, 1}, vehicle_port, Dolphin.MAVLink.Frame.encode(request, sysid: 255, compid: 190, seq: 0))
          assert_receive_message(fn m -> match?(%M.CommandAck{command: 512}, m) end)
        end
      end)

    pid = Process.get(:vehicle)
    assert Process.alive?(pid)
    assert {:ok, %{home: %{lat: 250.0}}} = GenServer.call(pid, :info)
    assert [_] = Regex.scan(~r/simulated vehicle 78: cannot encode HOME_POSITION.latitude = 2500000000/, log)
    # It still talks.
    assert_receive_message(fn m -> match?(%M.Heartbeat{}, m) end)
  end

  defp assert_receive_message(fun) do
    receive do
      {:udp, _, _, _, datagram} ->
        {frames, _} = Dolphin.MAVLink.Parser.feed(Dolphin.MAVLink.Parser.new(), datagram)
        unless Enum.any?(frames, &fun.(&1.message)), do: assert_receive_message(fun)
    after
      5_000 -> flunk("no such message from the vehicle")
    end
  end
end
