defmodule Dolphin.Sim.Copter.MissionTest do
  # The simulated copter's missions: targets, the current item, jumps, and
  # how progress is reported, on the model's state directly.
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.Copter
  alias Dolphin.Sim.Copter.Mission

  @home %{lat: 40.444233, lon: -7.375234, alt: 820.0}
  @gcs {255, 190}

  defp ready, do: Copter.new(1, @home, %{ekf_ready_ms: 0}) |> Copter.step(50) |> Copter.flush() |> elem(1)

  defp item(seq, command, fields \\ %{}) do
    struct(M.MissionItemInt, Map.merge(%{seq: seq, command: command, frame: 3, x: 0, y: 0, z: 0.0, autocontinue: 1, target_system: 1, target_component: 1}, fields))
  end

  # Uploads `items` after item 0 (home) through the mission protocol.
  defp upload(c, items) do
    items = [item(0, 16) | items]
    c = Copter.handle(c, %M.MissionCount{target_system: 1, target_component: 1, count: length(items), mission_type: 0}, @gcs)
    c = Enum.reduce(items, c, &Copter.handle(&2, &1, @gcs))
    {_, c} = Copter.flush(c)
    c
  end

  test "an item's point: 0,0 is where the vehicle is; a relative height is above home, 0 keeps the height" do
    c = %{ready() | n: 5.0, e: 6.0, alt: 830.0}
    assert Mission.item_target(c, item(1, 16, %{z: 20.0})) == {5.0, 6.0, 840.0}
    assert Mission.item_target(c, item(1, 16)) == {5.0, 6.0, 830.0}
    assert Mission.item_target(c, item(1, 16, %{frame: 0, z: 900.0})) == {5.0, 6.0, 900.0}

    p = Copter.offset(@home, 100, -50)
    {n, e, _} = Mission.item_target(c, item(1, 16, %{x: round(p.lat * 1.0e7), y: round(p.lon * 1.0e7), z: 20.0}))
    assert_in_delta n, 100.0, 0.02
    assert_in_delta e, -50.0, 0.02
  end

  test "a mission starts with a take-off when its first navigation command is one" do
    assert Mission.starts_with_takeoff?(upload(ready(), [item(1, 178, %{param2: 5.0}), item(2, 22, %{z: 10.0}), item(3, 16)]))
    refute Mission.starts_with_takeoff?(upload(ready(), [item(1, 16), item(2, 22, %{z: 10.0})]))
  end

  test "DO commands run at once, in a row, up to the next navigation command" do
    c = upload(ready(), [item(1, 178, %{param2: 4.0}), item(2, 16, %{z: 20.0})])
    c = Mission.start_item(%{c | mode: :auto}, 1)
    assert c.speed == 4.0
    assert c.current == 2 and c.mission_state == 3
    assert {:goto, +0.0, +0.0, 840.0} = c.nav
  end

  test "a loop of DO commands only is cut, and the mission ends" do
    c = upload(ready(), [item(1, 178, %{param2: 4.0}), item(2, 177, %{param1: 1.0, param2: -1.0})])
    c = Mission.start_item(%{c | mode: :auto}, 1)
    assert c.mission_state == 5 and c.current == 0
    assert Enum.any?(c.out, &match?({_, %M.Statustext{text: "Mission: too many commands without navigation"}}, &1))
  end

  test "a jump repeats its target as many times as asked" do
    c = upload(ready(), [item(1, 178, %{param2: 4.0}), item(2, 177, %{param1: 1.0, param2: 2.0}), item(3, 16)])
    c = Mission.start_item(%{c | mode: :auto}, 1)
    assert c.jumps == %{2 => 2} and c.current == 3
  end

  test "only the latest MISSION_CURRENT and MISSION_ITEM_REACHED of one loop are reported" do
    c = %{ready() | out: [{1, :old}]}
    c = Copter.say(c, %M.MissionCurrent{seq: 1})
    c = Copter.say(c, %M.MissionItemReached{seq: 1})
    c = Copter.say(c, %M.MissionCurrent{seq: 2})
    c = Copter.say(c, %M.Statustext{text: "x"})
    c = Mission.latest_reports(c, 1)
    assert [{1, %M.Statustext{}}, {1, %M.MissionCurrent{seq: 2}}, {1, %M.MissionItemReached{seq: 1}}, {1, :old}] = c.out
  end

  # What the vehicle process does after a pause of its host: the model's
  # time catches up with the clock in one go, 9 s of it here in a moment of
  # real time (the process gives the model real time: `real_ms`). ArduPilot
  # SITL's own time would have stood still.
  test "an upload under way is not ended by the model's time catching up after a pause of the host" do
    c = %{ready() | real_ms: 1_000}
    c = Copter.handle(c, %M.MissionCount{target_system: 1, target_component: 1, count: 3, mission_type: 0}, @gcs)
    c = Copter.handle(c, item(0, 16), @gcs)
    c = Enum.reduce(1..180, c, fn _, c -> Copter.step(c, 50) end)
    {out, c} = Copter.flush(c)
    refute Enum.any?(out, &match?({_, %M.Statustext{text: "Mission upload timeout"}}, &1))
    assert Enum.any?(out, &match?({_, %M.MissionRequest{seq: 1}}, &1))

    c = Enum.reduce([item(1, 16), item(2, 16)], c, &Copter.handle(&2, &1, @gcs))
    {out, _} = Copter.flush(c)
    assert Enum.any?(out, &match?({_, %M.MissionAck{type: 0}}, &1))

    # The same silence over 2 s of real time as well: the upload ends.
    c = %{ready() | real_ms: 1_000}
    c = Copter.handle(c, %M.MissionCount{target_system: 1, target_component: 1, count: 3, mission_type: 0}, @gcs)
    c = Copter.handle(c, item(0, 16), @gcs)
    c = Enum.reduce(1..180, %{c | real_ms: 3_001}, fn _, c -> Copter.step(c, 50) end)
    {out, _} = Copter.flush(c)
    assert Enum.any?(out, &match?({_, %M.Statustext{text: "Mission upload timeout"}}, &1))
  end

  test "a new mission resets the progress, unless flying one in AUTO" do
    c = upload(ready(), [item(1, 16), item(2, 16)])
    assert %{current: 0, mission_state: 2} = Mission.changed(%{c | current: 2, resume: 2})
    assert %{current: 2, resume: 2} = Mission.changed(%{c | mode: :auto, mission_state: 3, current: 2, resume: 2})
  end
end
