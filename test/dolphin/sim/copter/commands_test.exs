defmodule Dolphin.Sim.Copter.CommandsTest do
  # The simulated copter's command protocol: every command acked, with the
  # result ArduCopter gives, from the component it was addressed to.
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.Copter
  alias Dolphin.Sim.Copter.Commands

  @home %{lat: 40.444233, lon: -7.375234, alt: 820.0}
  @gcs {255, 190}

  defp ready(config \\ %{}), do: Copter.new(1, @home, Map.merge(%{ekf_ready_ms: 0}, config)) |> Copter.step(50) |> Copter.flush() |> elem(1)
  defp in_air(c, fields \\ %{}), do: struct(c, Map.merge(%{mode: :guided, armed: true, landed: :in_air, alt: @home.alt + 20, nav: {:hold, 0.0, 0.0, @home.alt + 20}}, fields))

  # Runs a COMMAND_LONG (`position` nil) or COMMAND_INT; returns the model and the ack's `{compid, result}`.
  defp run(c, command, params, position \\ nil, compid \\ 1) do
    params = Enum.map(params ++ List.duplicate(0.0, 7 - length(params)), &(&1 * 1.0))
    c = Commands.command(c, command, params, position, compid, @gcs)
    [{from, %M.CommandAck{command: ^command, result: result, target_system: 255, target_component: 190}}] = Enum.filter(c.out, &match?({_, %M.CommandAck{}}, &1))
    {%{c | out: []}, {from, result}}
  end

  test "arm, take off in GUIDED, and the take-off refused when not armed or already flying" do
    {c, {1, 4}} = run(ready(), 22, [0, 0, 0, 0, 0, 0, 10])
    {c, {1, 0}} = run(c, 176, [1, 4])
    {c, {1, 0}} = run(c, 400, [1])
    {c, {1, 0}} = run(c, 22, [0, 0, 0, 0, 0, 0, 10])
    assert {:spool_up, _, {:climb, +0.0, +0.0, 830.0}} = c.nav
    assert {_, {1, 4}} = run(in_air(c), 22, [0, 0, 0, 0, 0, 0, 10])
  end

  test "a GUIDED take-off to no height is refused, as ArduCopter's do_user_takeoff refuses one downwards" do
    {c, {1, 0}} = run(ready(), 176, [1, 4])
    {c, {1, 0}} = run(c, 400, [1])
    {c, {1, 4}} = run(c, 22, [0, 0, 0, 0, 0, 0, 0])
    assert c.nav == :idle and c.landed == :on_ground
    {c, {1, 4}} = run(c, 22, [0, 0, 0, 0, 0, 0, -5])
    assert {_, {1, 0}} = run(c, 22, [0, 0, 0, 0, 0, 0, 0.5])
  end

  test "a COMMAND_INT's point is in its frame: DO_REPOSITION to a point 30 m above home" do
    p = Copter.offset(@home, 0, 40)
    {c, {1, 0}} = run(in_air(ready(), %{mode: :loiter}), 192, [5, 1], {6, round(p.lat * 1.0e7), round(p.lon * 1.0e7), 30.0})
    assert c.mode == :guided and c.speed == 5.0
    assert {:goto, n, e, 850.0} = c.nav
    assert_in_delta n, 0.0, 0.01
    assert_in_delta e, 40.0, 0.01

    # Without bit 0 of p2, only in GUIDED.
    assert {_, {1, 4}} = run(in_air(ready(), %{mode: :loiter}), 192, [5, 0], {6, round(p.lat * 1.0e7), round(p.lon * 1.0e7), 30.0})
  end

  test "DO_SET_HOME and DO_REPOSITION to a point off the map are refused: the home stays one HOME_POSITION can carry" do
    c = ready()
    {c, {1, 0}} = run(c, 179, [0, 0, 0, 0, 41.0, -8.0, 100])
    assert %{lat: 41.0, lon: -8.0} = c.home
    assert {%{home: %{lat: 41.0}}, {1, 2}} = run(c, 179, [0, 0, 0, 0, 250.0, 400.0, 0])
    assert {_, {1, 2}} = run(c, 179, [0, 0, 0, 0, 0, 0, 0], {0, 2_100_000_000, 0, 0.0})
    assert {%{nav: nav}, {1, 4}} = run(in_air(c), 192, [5, 1, 0, 0, 91.0, 0.0, 20])
    refute match?({:goto, _, _, _}, nav)
  end

  test "MISSION_START without a mission fails; SET_MISSION_CURRENT out of range is denied" do
    assert {_, {1, 4}} = run(ready(), 300, [0, 0])
    assert {_, {1, 2}} = run(ready(), 224, [3])
  end

  test "a reboot is refused while armed, and asked of the vehicle process otherwise" do
    assert {_, {1, 4}} = run(%{ready() | armed: true}, 246, [1])
    c = Commands.command(ready(), 246, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], nil, 1, @gcs)
    assert [{1, %M.CommandAck{result: 0}}, {:reboot, nil}] = c.out
  end

  test "the unacked_commands fault: the command is run, its COMMAND_ACK never sent" do
    c = Commands.command(ready(%{unacked_commands: [176]}), 176, [1.0, 4.0 | List.duplicate(0.0, 5)], nil, 1, @gcs)
    refute Enum.any?(c.out, &match?({_, %M.CommandAck{}}, &1))
    assert c.mode == :guided
    assert {_, {1, 0}} = run(c, 400, [1])
  end

  test "camera commands: to the camera component when there is one, else to the autopilot" do
    assert {%{photos: 1}, {100, 0}} = run(ready(%{camera: true}), 2000, [0, 0, 1], nil, 100)
    assert {%{photos: 1}, {1, 0}} = run(ready(), 203, [0, 0, 0, 0, 1])
    # Addressed to a camera the vehicle does not have: the autopilot answers.
    assert {%{photos: 1}, {1, 0}} = run(ready(), 2000, [0, 0, 1], nil, 100)
  end

  # The order is ArduCopter's (SITL): a ground station that reads on only
  # after the ACK misses what came before it.
  test "requests: a known message is sent after the ACK (before it for GET_HOME_POSITION), an unknown one denied; unknown commands unsupported" do
    sent = fn command, params -> Commands.command(ready(), command, params ++ List.duplicate(0.0, 7 - length(params)), nil, 1, @gcs).out |> Enum.reverse() |> Enum.map(&elem(&1, 1).__struct__) end
    assert sent.(512, [242.0]) == [M.CommandAck, M.HomePosition]
    assert sent.(520, [1.0]) == [M.CommandAck, M.AutopilotVersion]
    assert sent.(179, [1.0]) == [M.CommandAck, M.HomePosition]
    assert sent.(410, []) == [M.HomePosition, M.CommandAck]
    assert {_, {1, 2}} = run(ready(), 512, [9999])
    assert {_, {1, 3}} = run(ready(), 31_000, [])
  end
end
