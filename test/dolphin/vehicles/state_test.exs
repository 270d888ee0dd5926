defmodule Dolphin.Vehicles.StateTest do
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.Frame
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Vehicles.{Modes, State}

  doctest Modes
  doctest Dolphin.Vehicles.State

  defp frame(message, opts \\ []), do: struct(Frame, Keyword.merge([sysid: 1, compid: 1, seq: 0, message: message], opts))
  defp fold(messages), do: Enum.reduce(messages, State.new(1), fn {m, opts}, s -> State.apply(s, frame(m, opts), 100) end)

  test "heartbeat: type, autopilot, mode by name, armed" do
    s = fold([{%M.Heartbeat{type: 2, autopilot: 3, base_mode: 0x81 + 0x08, custom_mode: 17, system_status: 4}, []}])
    assert {s.type, s.autopilot, s.mode, s.armed, s.system_status} == {2, :ardupilot, :brake, true, 4}

    plane = fold([{%M.Heartbeat{type: 1, autopilot: 3, custom_mode: 10}, []}])
    assert plane.mode == :auto and not plane.armed
    rover = fold([{%M.Heartbeat{type: 10, autopilot: 3, custom_mode: 4}, []}])
    assert rover.mode == :hold
    px4 = fold([{%M.Heartbeat{type: 2, autopilot: 12, custom_mode: 0x03040000}, []}])
    assert px4.mode == :loiter
    odd = fold([{%M.Heartbeat{type: 2, autopilot: 3, custom_mode: 99}, []}])
    assert odd.mode == {:custom, 99}
  end

  test "another component's heartbeat does not overwrite the vehicle; a camera is a payload" do
    s =
      fold([
        {%M.Heartbeat{type: 2, autopilot: 3, custom_mode: 4}, []},
        {%M.Heartbeat{type: 30, autopilot: 8}, [compid: 100]},
        {%M.Heartbeat{type: 18, autopilot: 8}, [compid: 191]}
      ])

    assert s.mode == :guided and s.type == 2
    assert MapSet.member?(s.components, :camera)

    # An ADS-B receiver (its own component, autopilot GENERIC) is not the vehicle.
    adsb = State.apply(s, frame(%M.Heartbeat{type: 27, autopilot: 0}, compid: 156), 200)
    assert {adsb.type, adsb.mode, adsb.autopilot} == {2, :guided, :ardupilot}
  end

  test "battery is unknown until reported; -1 stays unknown" do
    assert fold([]).battery == nil
    assert fold([{%M.SysStatus{battery_remaining: -1}, []}]).battery == nil
    assert fold([{%M.SysStatus{battery_remaining: 87}, []}]).battery == 0.87
    assert fold([{%M.BatteryStatus{id: 0, battery_remaining: 30}, []}]).battery == 0.3
    assert fold([{%M.BatteryStatus{id: 1, battery_remaining: 30}, []}]).battery == nil
  end

  test "position, home, mission progress, landed state, status texts" do
    # Before a position fix ArduPilot says 0, 0: no position.
    assert fold([{%M.GlobalPositionInt{lat: 0, lon: 0, relative_alt: -20}, []}]).position == nil

    s =
      fold([
        {%M.GlobalPositionInt{lat: 411_780_000, lon: -85_960_000, alt: 132_000, relative_alt: 20_500, hdg: 65_535, vx: 250, vy: -120, vz: -50}, []},
        {%M.HomePosition{latitude: 411_770_000, longitude: -85_950_000, altitude: 111_500}, []},
        {%M.MissionCurrent{seq: 3, total: 6, mission_state: 3}, []},
        {%M.MissionItemReached{seq: 2}, []},
        {%M.ExtendedSysState{landed_state: 2}, []},
        {%M.Statustext{severity: 6, text: "Reached command #2"}, []}
      ])

    # Velocity north, east and up (GLOBAL_POSITION_INT's vz is down).
    assert s.position == %{lat: 41.178, lon: -8.596, alt: 132.0, relative_alt: 20.5, heading: nil, velocity: {2.5, -1.2, 0.5}}
    assert s.home == %{lat: 41.177, lon: -8.595, alt: 111.5}
    assert s.mission == %{current: 3, total: 6, state: :active, reached: 2}
    assert s.landed == :in_air
    assert s.status_texts == [{6, "Reached command #2"}]
  end

  test "a mission being replaced forgets the previous one's progress; reaching an item of the same number is then a change" do
    s = fold([{%M.MissionCurrent{seq: 2, total: 3, mission_state: 5}, []}, {%M.MissionItemReached{seq: 2}, []}, {%M.SysStatus{battery_remaining: 80}, []}])
    assert s.mission == %{current: 2, total: 3, state: :complete, reached: 2}

    fresh = State.mission_replaced(s)
    assert fresh.mission == %{current: nil, total: nil, state: nil, reached: nil}
    assert State.changes(s, fresh) == [mission: fresh.mission]
    # Nothing else is forgotten.
    assert %{fresh | mission: s.mission} == s

    # The new mission's take-off has the number the last one reached.
    again = State.apply(fresh, frame(%M.MissionItemReached{seq: 2}), 200)
    assert State.changes(fresh, again) == [mission: %{current: nil, total: nil, state: nil, reached: 2}]
    started = State.apply(fresh, frame(%M.MissionCurrent{seq: 1, total: 4, mission_state: 3}), 200)
    assert started.mission == %{current: 1, total: 4, state: :active, reached: nil}
  end

  test "link quality: sequence gaps per component are counted as lost" do
    s = fold([{%M.Heartbeat{}, [seq: 254]}, {%M.Heartbeat{}, [seq: 255]}, {%M.Heartbeat{}, [seq: 2]}, {%M.Heartbeat{}, [seq: 0, compid: 100]}])
    assert s.link.received == 4
    assert s.link.lost == 2
    assert s.link.last_seen_ms == 100
  end

  test "changes lists what a subscriber should hear" do
    a = fold([{%M.Heartbeat{type: 2, autopilot: 3, custom_mode: 4}, []}])
    b = State.apply(a, frame(%M.SysStatus{battery_remaining: 50}), 200)
    assert State.changes(a, b) == [battery: 0.5]
    assert State.changes(b, State.apply(b, frame(%M.SysStatus{battery_remaining: 50}), 300)) == []
  end

  test "changes names every public field that changed, in the fields' order, and an equal number as no change" do
    a = fold([{%M.Heartbeat{type: 2, autopilot: 3, custom_mode: 4}, []}])
    fields = [:type, :autopilot, :mode, :armed, :system_status, :position, :home, :battery, :mission, :landed, :status_texts, :uid, :components, :sensors]
    changed = Enum.reduce(fields, a, fn field, s -> Map.put(s, field, {:new, field}) end)
    assert State.changes(a, changed) == Enum.map(fields, &{&1, {:new, &1}})
    assert State.changes(changed, Map.put(changed, :sensors, {:new, :sensors})) == []
    # A pack at 1 and at 1.0 is the same pack: no change to tell.
    assert State.changes(%{a | battery: 1}, %{a | battery: 1.0}) == []
  end
end
