defmodule Dolphin.Vehicles.CommandProtocolTest do
  # A scripted vehicle answers (or not) the commands of the ground station over
  # UDP on 127.0.0.1. Changes the clock speed-up: not async.
  use ExUnit.Case, async: false

  alias Dolphin.Test.Wait

  alias Dolphin.{Clock, CommandError, Link, Vehicles}
  alias Dolphin.Link.Connection
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Test.UDPPeer

  doctest Dolphin.CommandError

  setup do
    name = "cmd-#{System.unique_integer([:positive])}"
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: name)
    port = Connection.port(name)
    peer = UDPPeer.open()
    sysid = 20 + rem(System.unique_integer([:positive]), 200)
    # ack timeouts of 1.5 s of clock time become 15 ms of real time.
    Clock.set_speedup(100)

    on_exit(fn ->
      Clock.set_speedup(1)
      DynamicSupervisor.terminate_child(Dolphin.Link.Supervisor, link)
      Vehicles.forget(sysid)
    end)

    UDPPeer.send_message(peer, port, %M.Heartbeat{type: 2, autopilot: 3, custom_mode: 0}, sysid: sysid)
    Wait.until(fn -> match?({:ok, %{autopilot: :ardupilot}}, Vehicles.state(sysid)) end)
    # Position telemetry: the vehicle process stops asking for telemetry; its
    # own message-interval commands (unanswered here) are let run out first.
    UDPPeer.send_message(peer, port, %M.GlobalPositionInt{}, sysid: sysid, seq: 1)
    Wait.until(fn -> :sys.get_state(Vehicles.whereis(sysid)).ops == %{} end)
    %{peer: peer, port: port, sysid: sysid}
  end

  defp next_command(peer, command, timeout \\ 2_000),
    do: UDPPeer.receive_until(peer, &match?(%M.CommandLong{command: ^command}, &1.message), timeout).message

  defp ack(peer, port, sysid, command, result, extra \\ []),
    do: UDPPeer.send_message(peer, port, struct(M.CommandAck, [command: command, result: result, target_system: 255] ++ extra), sysid: sysid)

  test "a lost command is sent again with the confirmation counter incremented", %{peer: peer, port: port, sysid: sysid} do
    task = Task.async(fn -> Vehicles.arm(sysid) end)
    assert %M.CommandLong{confirmation: 0, param1: 1.0, target_system: ^sysid} = next_command(peer, 400)
    assert %M.CommandLong{confirmation: 1} = next_command(peer, 400)
    assert %M.CommandLong{confirmation: 2} = next_command(peer, 400)
    ack(peer, port, sysid, 400, 0)
    assert Task.await(task) == {:ok, :accepted}
  end

  test "a refusal names the command, the vehicle and the result", %{peer: peer, port: port, sysid: sysid} do
    # A long ack timeout: one attempt, however busy the machine.
    task = Task.async(fn -> Vehicles.arm(sysid, ack_timeout_ms: 100_000) end)
    next_command(peer, 400)
    ack(peer, port, sysid, 400, 4)
    assert {:error, %CommandError{result: :failed, attempts: 1} = e} = Task.await(task)
    assert Exception.message(e) == "vehicle #{sysid} refused MAV_CMD_COMPONENT_ARM_DISARM: MAV_RESULT_FAILED"
  end

  test "IN_PROGRESS stops retransmission and reports progress until the final answer", %{peer: peer, port: port, sysid: sysid} do
    me = self()
    # The wait after IN_PROGRESS (3 s of real time here) outlasts this test's pauses.
    task = Task.async(fn -> Vehicles.command(sysid, :mav_cmd_preflight_calibration, [1], progress_to: me, progress_timeout_ms: 300_000) end)
    next_command(peer, 241)
    ack(peer, port, sysid, 241, 5, progress: 40)
    assert_receive {:command_progress, 241, 40}, 2_000
    # Retransmissions sent before IN_PROGRESS arrived (a busy machine) are
    # drained; from here on, several ack timeouts pass with none.
    drain(peer)
    Process.sleep(100)
    refute_command(peer, 241)
    ack(peer, port, sysid, 241, 5, progress: 90)
    assert_receive {:command_progress, 241, 90}, 2_000
    ack(peer, port, sysid, 241, 0)
    assert Task.await(task) == {:ok, :accepted}
    refute_command(peer, 241)
  end

  test "no answer at all: a timeout error after the retries", %{peer: peer, sysid: sysid} do
    assert {:error, %CommandError{result: :timeout, attempts: 3} = e} = Vehicles.land(sysid, attempts: 3)
    assert Exception.message(e) =~ "did not answer MAV_CMD_NAV_LAND (3 attempts)"
    for c <- 0..2, do: assert(%M.CommandLong{confirmation: ^c} = next_command(peer, 21))
  end

  test "two commands with one id run one after the other", %{peer: peer, port: port, sysid: sysid} do
    t1 = Task.async(fn -> Vehicles.set_message_interval(sysid, 33, 100_000) end)
    assert %M.CommandLong{param1: 33.0} = next_command(peer, 511)
    t2 = Task.async(fn -> Vehicles.set_message_interval(sysid, 30, 50_000) end)
    ack(peer, port, sysid, 511, 0)
    assert Task.await(t1) == {:ok, :accepted}
    assert %M.CommandLong{param1: 30.0} = UDPPeer.receive_until(peer, &match?(%M.CommandLong{command: 511, param1: 30.0}, &1.message)).message
    ack(peer, port, sysid, 511, 2)
    assert {:error, %CommandError{result: :denied}} = Task.await(t2)
  end

  test "modes by name; a mode the vehicle does not have is refused before anything is sent", %{peer: peer, port: port, sysid: sysid} do
    task = Task.async(fn -> Vehicles.set_mode(sysid, :brake) end)
    assert %M.CommandLong{param1: 1.0, param2: 17.0} = next_command(peer, 176)
    ack(peer, port, sysid, 176, 0)
    assert Task.await(task) == {:ok, :accepted}

    assert {:error, %CommandError{result: :not_sent} = e} = Vehicles.set_mode(sysid, :warp)
    assert Exception.message(e) =~ "MAV_CMD_DO_SET_MODE not sent to vehicle #{sysid} (no mode :warp on this vehicle"
  end

  test "COMMAND_INT carries the position as integers", %{peer: peer, port: port, sysid: sysid} do
    task = Task.async(fn -> Vehicles.command_int(sysid, :mav_cmd_do_reposition, [-1], {41.178, -8.596, 30}) end)
    %M.CommandInt{x: 411_780_000, y: -85_960_000, z: 30.0, frame: 6, param1: -1.0} =
      UDPPeer.receive_until(peer, &match?(%M.CommandInt{}, &1.message)).message

    ack(peer, port, sysid, 192, 0)
    assert Task.await(task) == {:ok, :accepted}

    home = Task.async(fn -> Vehicles.set_home(sysid, {41.1780001, -8.5960001, 110.5}) end)
    %M.CommandInt{command: 179, frame: 0, x: 411_780_001, y: -85_960_001, z: 110.5} =
      UDPPeer.receive_until(peer, &match?(%M.CommandInt{command: 179}, &1.message)).message

    ack(peer, port, sysid, 179, 0)
    assert Task.await(home) == {:ok, :accepted}
  end

  test "an answer meant for another ground station, or from another component, is not ours", %{peer: peer, port: port, sysid: sysid} do
    task = Task.async(fn -> Vehicles.arm(sysid, attempts: 2) end)
    next_command(peer, 400)
    UDPPeer.send_message(peer, port, %M.CommandAck{command: 400, result: 0, target_system: 254}, sysid: sysid)
    UDPPeer.send_message(peer, port, %M.CommandAck{command: 400, result: 0, target_system: 255}, sysid: sysid, compid: 100)
    assert {:error, %CommandError{result: :timeout}} = Task.await(task)
  end

  test "caller mistakes are raised at the call, before anything is sent", %{sysid: sysid} do
    assert_raise ArgumentError, ~r/a MAV_CMD is 0..65535/, fn -> Vehicles.command(sysid, 70_000) end
    assert_raise ArgumentError, ~r/command parameters must be numbers/, fn -> Vehicles.command(sysid, 400, ["1"]) end
    assert_raise ArgumentError, ~r/position must be/, fn -> Vehicles.command_int(sysid, 192, [], {95.0, 0, 0}) end
    assert_raise ArgumentError, ~r/mission_type must be/, fn -> Vehicles.clear_mission(sysid, mission_type: :bogus) end
    bad = %M.MissionItemInt{command: 16, x: 47.39}
    assert_raise ArgumentError, ~r/mission item 1: cannot encode MISSION_ITEM_INT.x = 47.39/, fn -> Vehicles.upload_mission(sysid, [%M.MissionItemInt{}, bad]) end
    assert Vehicles.whereis(sysid) != nil
  end

  test "a command queued by a caller that went away is never sent", %{peer: peer, port: port, sysid: sysid} do
    t1 = Task.async(fn -> Vehicles.arm(sysid) end)
    next_command(peer, 400)
    {pid, ref} = spawn_monitor(fn -> Vehicles.command(sysid, 400, [4]) end)
    Wait.until(fn -> :queue.len(Map.get(:sys.get_state(Vehicles.whereis(sysid)).queued, 400, :queue.new())) == 1 end)
    Process.exit(pid, :kill)
    assert_receive {:DOWN, ^ref, :process, ^pid, :killed}
    Wait.until(fn -> :queue.is_empty(Map.get(:sys.get_state(Vehicles.whereis(sysid)).queued, 400, :queue.new())) end)
    ack(peer, port, sysid, 400, 0)
    assert Task.await(t1) == {:ok, :accepted}
    assert_raise ExUnit.AssertionError, fn -> UDPPeer.receive_until(peer, &match?(%M.CommandLong{command: 400, param1: 4.0}, &1.message), 200) end
  end

  test "an unknown vehicle is an error, not a crash" do
    assert {:error, %CommandError{result: :vehicle_gone, detail: "no such vehicle"}} = Vehicles.takeoff(254, 10)
    assert_raise ArgumentError, ~r/unknown MAV_CMD :mav_cmd_warp/, fn -> Vehicles.command(1, :mav_cmd_warp) end
  end

  defp drain(peer) do
    case :gen_udp.recv(peer, 0, 20) do
      {:ok, _} -> drain(peer)
      {:error, :timeout} -> :ok
    end
  end

  defp refute_command(peer, command) do
    assert_raise ExUnit.AssertionError, fn -> next_command(peer, command, 100) end
  end

end
