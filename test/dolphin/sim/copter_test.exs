defmodule Dolphin.Sim.CopterTest do
  # The simulated ArduCopter as a pure model: messages in, time stepped, what
  # it says out. Deterministic, no sockets.
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.Copter

  import Dolphin.Test.SimModel

  @home %{lat: 40.444233, lon: -7.375234, alt: 820.0}
  @step 50

  # --- driving the model -------------------------------------------------------

  defp boot(config \\ %{}), do: Copter.new(1, @home, Map.merge(%{ekf_ready_ms: 5_000}, config))

  # Steps `ms` of vehicle time; returns the model and everything it said, with the time it said it.
  defp run(c, ms, said \\ []) do
    Enum.reduce(1..div(ms, @step), {c, said}, fn _, {c, said} ->
      {out, c} = c |> Copter.step(@step) |> Copter.flush()
      {c, said ++ Enum.map(out, fn {compid, m} -> {c.time_ms, compid, m} end)}
    end)
  end

  # Steps until `fun.(c)` holds (at most `max_ms`).
  defp run_until(c, fun, max_ms, said \\ []) do
    cond do
      fun.(c) ->
        {c, said}

      max_ms <= 0 ->
        flunk("not reached in time: mode #{c.mode}, armed #{c.armed}, landed #{c.landed}, alt #{c.alt}, nav #{inspect(c.nav)}")

      true ->
        {c, said} = run(c, @step, said)
        run_until(c, fun, max_ms - @step, said)
    end
  end

  defp messages(said, module), do: for({t, _, %^module{} = m} <- said, do: {t, m})

  defp item(seq, command, {lat, lon, alt}, params \\ %{}) do
    fields = Map.merge(%{seq: seq, command: command, frame: 6, x: round(lat * 1.0e7), y: round(lon * 1.0e7), z: alt * 1.0, autocontinue: 1, target_system: 1, target_component: 1}, params)
    struct(M.MissionItemInt, fields)
  end

  defp ready(config \\ %{}) do
    {c, _} = boot(config) |> run(5_000)
    c
  end

  defp north_east(n, e), do: Copter.offset(@home, n, e) |> then(&{&1.lat, &1.lon})

  defp distance_m(c, {lat, lon}) do
    {n, e} = Copter.ne(c, lat, lon)
    :math.sqrt((c.n - n) ** 2 + (c.e - e) ** 2)
  end

  defp flying_mission(items, config \\ %{}) do
    c = ready(config) |> upload(items)
    {c, 0, _} = command(c, 176, [1, 4])
    {c, 0, _} = command(c, 400, [1])
    {c, 0, _} = command(c, 300, [0, 0])
    c
  end

  # A mission: home, take off to 20 m, a waypoint 60 m north, loiter 5 s 60 m north-east, RTL.
  defp standard_mission do
    wp1 = north_east(60, 0)
    wp2 = north_east(60, 60)

    [
      item(0, 16, {@home.lat, @home.lon, 0}),
      item(1, 22, {0, 0, 20}),
      item(2, 16, Tuple.append(wp1, 20)),
      item(3, 19, Tuple.append(wp2, 20), %{param1: 5.0, param3: 10.0}),
      item(4, 20, {0, 0, 0})
    ]
  end

  # --- telemetry ---------------------------------------------------------------

  # What the vehicle process does when it steps several times at once (a
  # pause of its host): it sends the present, as an autopilot's late
  # telemetry loop does, not a burst of old positions.
  test "several steps at once: the latest of each stream only, everything else kept" do
    {c, _} = boot(%{ekf_ready_ms: 0}) |> run(1_000)
    {c, []} = tell(c, %M.RequestDataStream{target_system: 1, target_component: 1, req_stream_id: 0, req_message_rate: 4, start_stop: 1})
    caught_up = Enum.reduce(1..40, c, fn _, c -> Copter.advance(c, @step) end)
    caught_up = Copter.text(caught_up, 4, "between the steps")
    {out, _} = caught_up |> Dolphin.Sim.Streams.due() |> Copter.flush()

    assert [%M.GlobalPositionInt{time_boot_ms: at}] = for({1, %M.GlobalPositionInt{} = m} <- out, do: m)
    assert at >= caught_up.time_ms - 250
    assert [_] = for({1, %M.Heartbeat{}} <- out, do: :heartbeat)
    assert [%M.Statustext{text: "between the steps"}] = for({_, %M.Statustext{} = m} <- out, do: m)
    # Stepped with their streams, the same two seconds hold each of them in turn.
    {all, _} = Enum.reduce(1..40, c, fn _, c -> Copter.step(c, @step) end) |> Copter.flush()
    assert length(for({1, %M.GlobalPositionInt{}} <- all, do: :position)) in 8..9
  end

  test "sends only heartbeats, statustexts and TIMESYNC until streams are asked for" do
    {c, said} = boot() |> run(10_000)
    kinds = said |> Enum.map(fn {_, _, %m{}} -> m end) |> Enum.uniq() |> Enum.sort()
    # (HOME_POSITION once, when home is set.)
    assert kinds == [M.HomePosition, M.Heartbeat, M.Statustext, M.Timesync] |> Enum.sort()
    {_, [%M.Timesync{tc1: tc1, ts1: 42}]} = tell(c, %M.Timesync{tc1: 0, ts1: 42})
    assert tc1 > 0
    assert length(messages(said, M.Heartbeat)) in 9..11

    {c, []} = tell(c, %M.RequestDataStream{target_system: 1, target_component: 1, req_stream_id: 0, req_message_rate: 4, start_stop: 1})
    {c, said} = run(c, 1_000)
    assert length(messages(said, M.GlobalPositionInt)) in 4..5
    assert length(messages(said, M.SysStatus)) in 4..5
    assert messages(said, M.ExtendedSysState) == []

    {c, 0, _} = command(c, 511, [245, 200_000])
    {_c, said} = run(c, 1_000)
    assert length(messages(said, M.ExtendedSysState)) in 5..6
  end

  test "a camera component has its own heartbeat; photos are counted and reported" do
    {c, said} = boot(%{camera: true}) |> run(2_000)
    assert [{_, 100, %M.Heartbeat{type: 30}} | _] = for({_, 100, %M.Heartbeat{}} = h <- said, do: h)

    # One photo (DO_DIGICAM_CONTROL), then three a second apart (IMAGE_START_CAPTURE to the camera).
    {c, 0, _} = command(c, 203, [0, 0, 0, 0, 1])
    {c, out} = tell(c, %M.CommandLong{target_system: 1, target_component: 100, command: 2000, param2: 1.0, param3: 3.0})
    assert [%M.CameraImageCaptured{image_index: 1}, %M.CommandAck{command: 2000, result: 0}] = out
    {c, said} = run(c, 5_000)
    assert c.photos == 4
    assert [{3000, 100, 2}, {4000, 100, 3}] == for({t, compid, %M.CameraImageCaptured{image_index: i}} <- said, do: {t, compid, i})
  end

  # --- arming -------------------------------------------------------------------

  test "arming is refused until the position estimate is ready, in AUTO, and on a low battery" do
    c = boot()
    {c, 4, ["Arm: Need Position Estimate"]} = command(c, 400, [1])
    # The forced arm skips the checks.
    {c, 0, _} = command(c, 400, [1, 21_196])
    {c, 0, _} = command(c, 400, [0])

    {c, _} = run(c, 5_000)
    assert c.home != nil
    c = upload(c, standard_mission())
    {c, 0, _} = command(c, 176, [1, 3])
    {c, 4, ["Arm: AUTO mode not armable"]} = command(c, 400, [1])

    {c, 0, _} = command(c, 176, [1, 4])
    {_c, 4, ["Arm: Battery 1 below minimum arming capacity"]} = command(%{c | battery: 0.1}, 400, [1])
    {_c, 0, ["Arming motors"]} = command(c, 400, [1])
  end

  test "repeats the pre-arm failure while the position estimate is not ready" do
    {_c, said} = boot(%{ekf_ready_ms: 70_000}) |> run(65_000)
    assert [{_, %M.Statustext{severity: 2, text: "PreArm: Need Position Estimate"}} | _] = pre = messages(said, M.Statustext)
    assert length(pre) == 3
  end

  test "disarms itself 10 s after arming on the ground" do
    c = ready()
    {c, 0, _} = command(c, 176, [1, 4])
    {c, 0, _} = command(c, 400, [1])
    {c, said} = run(c, 9_500)
    assert c.armed
    {c, said} = run(c, 1_000, said)
    refute c.armed
    assert "Disarming motors" in texts(said)
  end

  # --- missions -----------------------------------------------------------------

  test "flies a mission item by item, at the planned points, and lands at home" do
    items = standard_mission()
    c = flying_mission(items)
    {c, said} = run_until(c, &(&1.mission_state == 5 and not &1.armed), 200_000)

    reached = messages(said, M.MissionItemReached)
    assert Enum.map(reached, fn {_, m} -> m.seq end) == [1, 2, 3, 4]

    # Where it was when each item was reached, replayed.
    {c2, said2} = flying_mission(items) |> run_until(&match?(%{item: %{seq: 3}}, &1), 200_000)
    [{_, %{seq: 2}} | _] = Enum.reverse(messages(said2, M.MissionItemReached))
    assert distance_m(c2, north_east(60, 0)) <= 3.0
    assert_in_delta c2.alt, 840, 1.0

    # The loiter: 5 s at its point, circling 10 m around it.
    [{t_start, _}] = for {t, _, %M.Statustext{text: "Mission: 3 LoitTime"}} <- said, do: {t, nil}
    [{t_done, _}] = for {t, %{seq: 3}} <- reached, do: {t, nil}
    assert t_done - t_start >= 5_000

    # The RTL item is reached only after landing: after "Disarming motors".
    texts = for {t, _, %M.Statustext{text: text}} <- said, do: {t, text}
    {t_disarm, _} = Enum.find(texts, fn {_, text} -> text == "Disarming motors" end)
    [{t_rtl, _}] = for {t, %{seq: 4}} <- reached, do: {t, nil}
    assert t_rtl >= t_disarm

    assert c.landed == :on_ground and c.mode == :auto
    assert distance_m(c, {@home.lat, @home.lon}) < 2.5
    assert {_, %M.MissionCurrent{seq: 0, mission_state: 5}} = List.last(messages(said, M.MissionCurrent))
  end

  test "a loiter for turns circles the point at its radius the given number of times" do
    centre = north_east(40, 0)

    items = [
      item(0, 16, {@home.lat, @home.lon, 0}),
      item(1, 22, {0, 0, 15}),
      item(2, 18, Tuple.append(centre, 15), %{param1: 2.0, param3: 20.0}),
      item(3, 21, {0, 0, 0})
    ]

    c = flying_mission(items)
    {c, _} = run_until(c, &match?({:circle, _, _, _, _, _, _}, &1.nav), 100_000)
    {c, said} = run(c, 5_000)
    # Once settled on the circle, it stays 20 m from the centre.
    assert_in_delta distance_m(c, centre), 20, 2.0
    {_c, said} = run_until(c, &(&1.current == 3), 200_000, said)
    [{t, _}] = for {t, %{seq: 2}} <- messages(said, M.MissionItemReached), do: {t, nil}
    # Two turns of 2π·20 m at 5 m/s take about 50 s.
    assert t - c.time_ms + 5_000 >= 40_000
  end

  test "MISSION_CURRENT: not started, active, interrupted and resumed, complete" do
    c = ready() |> upload(standard_mission())
    {c, said} = run(c, 100)
    assert [] == messages(said, M.MissionCurrent)
    {c, out} = tell(c, %M.RequestDataStream{target_system: 1, target_component: 1, req_stream_id: 2, req_message_rate: 2, start_stop: 1})
    assert out == []
    {c, said} = run(c, 1_000)
    assert {_, %M.MissionCurrent{total: 4, mission_state: 2}} = List.last(messages(said, M.MissionCurrent))

    {c, 0, _} = command(c, 176, [1, 4])
    {c, 0, _} = command(c, 400, [1])
    {c, 0, _} = command(c, 300, [0, 0])
    {c, _} = run_until(c, &(&1.current == 2), 60_000)
    {c, said} = run(c, 1_000)
    assert {_, %M.MissionCurrent{seq: 2, mission_state: 3, mission_mode: 1}} = List.last(messages(said, M.MissionCurrent))

    # BRAKE interrupts: state 2, seq kept; it stops and holds.
    {c, 0, _} = command(c, 176, [1, 17])
    {c, said} = run(c, 5_000)
    assert {_, %M.MissionCurrent{seq: 2, mission_state: 2}} = List.last(messages(said, M.MissionCurrent))
    held = {c.n, c.e, c.alt}
    {c, _} = run(c, 20_000)
    assert_in_delta elem(held, 0), c.n, 0.5
    assert_in_delta elem(held, 1), c.e, 0.5
    assert_in_delta elem(held, 2), c.alt, 0.5

    # Back to AUTO: resumes at the interrupted item.
    {c, 0, _} = command(c, 176, [1, 3])
    assert c.current == 2
    {_c, said} = run_until(c, &(&1.mission_state == 5), 200_000)
    assert [2, 3, 4] == for({_, %{seq: s}} <- messages(said, M.MissionItemReached), do: s)
  end

  test "DO_JUMP repeats, DO_CHANGE_SPEED changes the cruise speed" do
    a = north_east(30, 0)

    items = [
      item(0, 16, {@home.lat, @home.lon, 0}),
      item(1, 22, {0, 0, 10}),
      item(2, 178, {0, 0, 0}, %{param1: 1.0, param2: 4.0, frame: 2}),
      item(3, 16, Tuple.append(a, 10)),
      item(4, 16, {@home.lat, @home.lon, 10}),
      item(5, 177, {0, 0, 0}, %{param1: 3.0, param2: 2.0, frame: 2}),
      item(6, 21, {0, 0, 0})
    ]

    c = flying_mission(items)
    # As ArduCopter: a final NAV_LAND is never reported reached; the vehicle
    # disarms with the land item current and the mission still ACTIVE.
    {c, said} = run_until(c, &(&1.landed == :on_ground and not &1.armed), 300_000)
    assert c.speed == 4.0
    seqs = for {_, %{seq: s}} <- messages(said, M.MissionItemReached), do: s
    # The take-off and the speed change end in one loop: ArduCopter reports
    # only the latest of them.
    assert seqs == [2, 3, 4, 3, 4, 3, 4]
    # Then the mission is reset to item 1, still ACTIVE, in AUTO.
    assert {c.current, c.mission_state, c.mode} == {1, 3, :auto}
    assert [{_, %{seq: 1, mission_state: 3}}, {_, %{seq: 6, mission_state: 3}} | _] = Enum.reverse(messages(said, M.MissionCurrent))
  end

  test "a NAV_LAND followed by a take-off is reached on the ground and flown on from, armed" do
    items = [
      item(0, 16, {@home.lat, @home.lon, 0}),
      item(1, 22, {0, 0, 10}),
      item(2, 21, {0, 0, 0}),
      item(3, 22, {0, 0, 10}),
      item(4, 20, {0, 0, 0})
    ]

    c = flying_mission(items)
    {c, said} = run_until(c, &(&1.mission_state == 5 and not &1.armed), 300_000)
    assert [1, 2, 3, 4] == for({_, %{seq: s}} <- messages(said, M.MissionItemReached), do: s)
    # One disarm only: at the end, after the RTL's landing.
    assert 1 == Enum.count(texts(said), &(&1 == "Disarming motors"))
    assert c.landed == :on_ground
  end

  test "a mission's take-off to the ground's own height climbs 1 m, as ArduCopter's does (ModeAuto::takeoff_start), and the mission flies on" do
    items = [
      item(0, 16, {@home.lat, @home.lon, 0}),
      item(1, 22, {0, 0, @home.alt}, %{frame: 0, param1: 860.0}),
      item(2, 16, Tuple.append(north_east(60, 0), 20)),
      item(3, 20, {0, 0, 0})
    ]

    c = flying_mission(items)
    {c, said} = run_until(c, &(&1.current == 2), 60_000)
    # Reached at its 1 m (less ArduCopter's half-metre margin), not higher.
    assert c.alt - @home.alt >= 0.5 and c.alt - @home.alt <= 1.05
    assert c.landed == :in_air
    assert [{_, %{seq: 1}}] = messages(said, M.MissionItemReached)
    {c, said} = run_until(c, &(&1.mission_state == 5 and not &1.armed), 300_000)
    assert [2, 3] == for({_, %{seq: s}} <- messages(said, M.MissionItemReached), do: s)
    assert c.landed == :on_ground
  end

  test "touching the ground after a take-off to 1 m is a landing: the land detector disarms" do
    items = [
      item(0, 16, {@home.lat, @home.lon, 0}),
      item(1, 22, {0, 0, @home.alt}, %{frame: 0}),
      item(2, 16, Tuple.append(north_east(100, 0), @home.alt), %{frame: 0}),
      item(3, 20, {0, 0, 0})
    ]

    c = flying_mission(items)
    {c, said} = run_until(c, &(not &1.armed), 60_000)
    assert "Disarming motors" in texts(said)
    assert c.landed == :on_ground and c.current == 2 and c.mission_state == 3
  end

  test "a loop of commands that complete at once is cut; DO commands before the take-off do not hide it" do
    items = [
      item(0, 16, {@home.lat, @home.lon, 0}),
      item(1, 178, {0, 0, 0}, %{param1: 1.0, param2: 5.0, frame: 2}),
      item(2, 22, {0, 0, 10}),
      item(3, 178, {0, 0, 0}, %{param1: 1.0, param2: 6.0, frame: 2}),
      item(4, 177, {0, 0, 0}, %{param1: 3.0, param2: -1.0, frame: 2})
    ]

    # CHANGE_SPEED first, then the take-off: ArduCopter starts it (starts_with_takeoff_cmd skips DO commands).
    c = flying_mission(items)
    assert c.mode == :auto
    {c, said} = run_until(c, &(&1.mission_state == 5), 60_000)
    assert "Mission: too many commands without navigation" in texts(said)
    assert c.armed and c.landed == :in_air
  end

  # --- modes --------------------------------------------------------------------

  defp airborne(alt \\ 20) do
    c = ready()
    {c, 0, _} = command(c, 176, [1, 4])
    {c, 0, _} = command(c, 400, [1])
    {c, 0, _} = command(c, 22, [0, 0, 0, 0, 0, 0, alt])
    {c, _} = run_until(c, &(&1.alt >= @home.alt + alt - 0.3), 60_000)
    c
  end

  test "GUIDED takes off, holds, and flies to a DO_REPOSITION target" do
    c = airborne()
    {c, _} = run(c, 20_000)
    assert abs(c.n) < 0.5 and abs(c.e) < 0.5
    {lat, lon} = north_east(100, 50)
    cmd = %M.CommandInt{target_system: 1, target_component: 1, command: 192, frame: 6, param1: -1.0, x: round(lat * 1.0e7), y: round(lon * 1.0e7), z: 30.0}
    {c, [%M.CommandAck{result: 0}]} = tell(c, cmd)
    {c, _} = run(c, 30_000)
    assert distance_m(c, {lat, lon}) < 0.5
    assert_in_delta c.alt, 850, 0.3
  end

  test "LOITER with no RC throttle descends, lands and disarms; LAND and RTL land" do
    c = airborne()
    {c, 0, _} = command(c, 176, [1, 5])
    {c, said} = run_until(c, &(not &1.armed), 60_000)
    assert c.landed == :on_ground and "Disarming motors" in texts(said)

    c = airborne()
    {c, 0, _} = command(c, 21, [])
    assert c.mode == :land
    {c, _} = run_until(c, &(not &1.armed), 60_000)
    assert c.landed == :on_ground

    c = airborne()
    {c, 0, _} = command(c, 192, [-1, 0, 0, 0] ++ Tuple.to_list(north_east(80, 0)) ++ [840])
    {c, _} = run(c, 20_000)
    {c, 0, _} = command(c, 20, [])
    assert c.mode == :rtl
    {c, _} = run_until(c, &(not &1.armed), 120_000)
    assert distance_m(c, {@home.lat, @home.lon}) < 2.5
  end

  test "AUTOPILOT_VERSION on request, with a unique id of its own, as a board's serial number" do
    {c, out} = tell(boot(), %M.CommandLong{target_system: 1, target_component: 1, command: 520, param1: 1.0})
    assert [%M.AutopilotVersion{uid: uid}] = for(%M.AutopilotVersion{} = m <- out, do: m) ++ for({_, _, %M.AutopilotVersion{} = m} <- out, do: m)
    assert uid == c.uid and uid > 0
    # Another vehicle with the same system id is another autopilot.
    assert boot().uid != c.uid
  end

  test "unknown modes and commands are refused with an ack" do
    c = ready()
    {c, 4, _} = command(c, 176, [1, 99])
    {_c, 3, _} = command(c, 31_000, [])
  end

  # --- battery ------------------------------------------------------------------

  test "the battery drains about 0.25 % a second in flight and charges on the ground at home" do
    c = airborne()
    before = c.battery
    {c, _} = run(c, 60_000)
    drained = (before - c.battery) * 100 / 60
    assert drained > 0.2 and drained < 0.32

    {c, 0, _} = command(c, 21, [])
    {c, _} = run_until(c, &(not &1.armed), 60_000)
    low = c.battery
    {c, _} = run(c, 20_000)
    assert_in_delta c.battery - low, 20 * 0.005, 0.001
  end

  test "battery warnings, and the failsafe when it is enabled" do
    c = airborne() |> Map.put(:battery, 0.205)
    {c, said} = run(c, 5_000)
    assert Enum.any?(texts(said), &String.starts_with?(&1, "Battery 1 is low"))
    # Off by default (BATT_FS_LOW_ACT 0): it goes on flying in GUIDED.
    assert c.mode == :guided

    c = ready(%{battery_failsafe: :rtl})
    {c, 0, _} = command(c, 176, [1, 4])
    {c, 0, _} = command(c, 400, [1])
    {c, 0, _} = command(c, 22, [0, 0, 0, 0, 0, 0, 20])
    {c, _} = run_until(c, &(&1.landed == :in_air), 60_000)
    {c, said} = run(%{c | battery: 0.201}, 5_000)
    assert "Battery Failsafe" in texts(said)
    assert c.mode == :rtl
  end

  test "milliseconds since boot wrap at 2^32, as ArduPilot's do" do
    c = %{boot() | time_ms: Bitwise.bsl(1, 32) + 1_234}
    assert %M.Attitude{time_boot_ms: 1_234} = Dolphin.Sim.Streams.message(c, 30)
    assert %M.GlobalPositionInt{time_boot_ms: 1_234} = Dolphin.Sim.Streams.message(c, 33)
    # And the frames encode.
    assert is_binary(Dolphin.MAVLink.Frame.encode(Dolphin.Sim.Streams.message(c, 33), sysid: 1, compid: 1, seq: 0))
  end
end
