defmodule Dolphin.Vehicles.CommandProtocolTest do
  # A scripted vehicle answers (or not) the commands of the ground station over UDP on
  # 127.0.0.1. Its own Dolphin.Instance (its vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.Test.Wait

  alias Dolphin.{Clock, CommandError, Link, Vehicles}
  alias Dolphin.Link.Connection
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Test.UDPPeer

  doctest Dolphin.CommandError
  doctest Dolphin.ParamError

  setup do
    name = "cmd-#{System.unique_integer([:positive])}"
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: name)
    port = Connection.port(name)
    peer = UDPPeer.open()
    sysid = 20 + rem(System.unique_integer([:positive]), 200)
    # Ack timeouts of 1.5 s of clock time become 150 ms of real time. Not
    # faster: the ground station's heartbeats come as fast (10 a second here),
    # and a peer that reads only when a test looks must not see its socket's
    # buffer fill up with them while a busy machine holds the test back.
    Clock.set_speedup(10)

    Dolphin.Test.Instance.on_exit(fn ->
      Clock.set_speedup(1)
      DynamicSupervisor.terminate_child(Dolphin.Instance.names().links, link)
      Vehicles.forget(sysid)
      Dolphin.Vehicles.Settings.clear(sysid)
    end)

    # The scripted vehicle is silent between a test's exchanges: never lost
    # (a reconnection would ask for telemetry again, and its commands would
    # mix with a test's), however long a busy machine holds the test up.
    {:error, :unknown_vehicle} = Vehicles.set_timeout(sysid, 3_600_000)
    UDPPeer.send_message(peer, port, %M.Heartbeat{type: 2, autopilot: 3, custom_mode: 0}, sysid: sysid)
    Wait.until(fn -> match?({:ok, %{autopilot: :ardupilot}}, Vehicles.state(sysid)) end)
    # Position telemetry: the vehicle process stops asking for telemetry; its
    # own message-interval commands are answered here, so that none is left
    # to mix with a test's.
    UDPPeer.send_message(peer, port, %M.GlobalPositionInt{}, sysid: sysid, seq: 1)

    # Settled: the position heard (no further round of requests), nothing in
    # flight or queued. (A command may end between the look at its process
    # and the wait for its frame, on a busy machine: then no frame comes, and
    # the next look sees it gone.)
    Wait.until(fn ->
      vehicle = :sys.get_state(Vehicles.whereis(sysid))

      (vehicle.requests_left == 0 and vehicle.ops == %{} and Enum.all?(Map.values(vehicle.queued), &:queue.is_empty/1)) or
        (answer_interval_request(peer, port, sysid) && false)
    end)

    %{peer: peer, port: port, sysid: sysid, link: name}
  end

  defp answer_interval_request(peer, port, sysid) do
    UDPPeer.receive_until(peer, &match?(%M.CommandLong{command: 511}, &1.message), 1_000)
    UDPPeer.send_message(peer, port, %M.CommandAck{command: 511, result: 0, target_system: 255, target_component: 190}, sysid: sysid)
  rescue
    ExUnit.AssertionError -> nil
  end

  # The test answers each command itself, after however long a busy machine
  # takes to run it: an ack timeout of an hour of clock time (6 minutes of real
  # time) keeps such a command to one attempt. The tests about retransmission
  # use `@until_answered` instead: retries at the usual pace, never giving up.
  @one_attempt [ack_timeout_ms: 3_600_000]
  @until_answered [attempts: 1_000_000]

  defp next_command(peer, command, timeout \\ 10_000),
    do: UDPPeer.receive_until(peer, &match?(%M.CommandLong{command: ^command}, &1.message), timeout).message

  defp ack(peer, port, sysid, command, result, extra \\ []),
    do: UDPPeer.send_message(peer, port, struct(M.CommandAck, [command: command, result: result, target_system: 255] ++ extra), sysid: sysid)

  test "a lost command is sent again with the confirmation counter incremented", %{peer: peer, port: port, sysid: sysid} do
    task = Task.async(fn -> Vehicles.arm(sysid, @until_answered) end)
    assert %M.CommandLong{confirmation: 0, param1: 1.0, target_system: ^sysid} = next_command(peer, 400)
    assert %M.CommandLong{confirmation: 1} = next_command(peer, 400)
    assert %M.CommandLong{confirmation: 2} = next_command(peer, 400)
    Process.sleep(300)
    ack(peer, port, sysid, 400, 0)
    assert Task.await(task) == {:ok, :accepted}
  end

  test "a refusal names the command, the vehicle and the result", %{peer: peer, port: port, sysid: sysid} do
    task = Task.async(fn -> Vehicles.arm(sysid, @one_attempt) end)
    next_command(peer, 400)
    ack(peer, port, sysid, 400, 4)
    assert {:error, %CommandError{result: :failed, attempts: 1} = e} = Task.await(task)
    assert Exception.message(e) == "vehicle #{sysid} refused MAV_CMD_COMPONENT_ARM_DISARM: MAV_RESULT_FAILED"
  end

  test "IN_PROGRESS stops retransmission and reports progress until the final answer", %{peer: peer, port: port, sysid: sysid, link: link} do
    me = self()
    # Retransmitted until IN_PROGRESS comes, however late; the wait after it
    # (a day of real time here) outlasts any pause of this test.
    opts = [progress_to: me, progress_timeout_ms: 864_000_000] ++ @until_answered
    task = Task.async(fn -> Vehicles.command(sysid, :mav_cmd_preflight_calibration, [1], opts) end)
    next_command(peer, 241)
    Process.sleep(300)
    ack(peer, port, sysid, 241, 5, progress: 40)
    assert_receive {:command_progress, 241, 40}, 10_000
    # Retransmissions sent before IN_PROGRESS arrived (a busy machine) are
    # drained; from here on, several ack timeouts pass with none.
    drain(peer, link)
    Process.sleep(5 * Clock.retry_real_ms(1_500))
    refute_command(peer, 241)
    ack(peer, port, sysid, 241, 5, progress: 90)
    assert_receive {:command_progress, 241, 90}, 10_000
    ack(peer, port, sysid, 241, 0)
    assert Task.await(task) == {:ok, :accepted}
    refute_command(peer, 241)
  end

  test "no answer at all: a timeout error after the retries", %{peer: peer, sysid: sysid} do
    assert {:error, %CommandError{result: :timeout, attempts: 3} = e} = Vehicles.land(sysid, attempts: 3)
    assert Exception.message(e) =~ "did not answer MAV_CMD_NAV_LAND (3 attempts)"
    for c <- 0..2, do: assert(%M.CommandLong{confirmation: ^c} = next_command(peer, 21))
  end

  describe "parameters" do
    defp param_value(peer, port, sysid, name, value),
      do: UDPPeer.send_message(peer, port, %M.ParamValue{param_id: name, param_value: value, param_type: 9, param_count: 1, param_index: 0}, sysid: sysid)

    test "a set is done when the vehicle answers with the value; another value kept is a refusal; a read gives the value", %{peer: peer, port: port, sysid: sysid} do
      task = Task.async(fn -> Vehicles.set_param(sysid, "FENCE_ACTION", 1, @one_attempt) end)
      assert %M.ParamSet{param_id: "FENCE_ACTION", param_value: 1.0, param_type: 9, target_system: ^sysid} = UDPPeer.receive_until(peer, &match?(%M.ParamSet{}, &1.message)).message
      # Another parameter's value is not this one's answer.
      param_value(peer, port, sysid, "FENCE_TYPE", 7.0)
      param_value(peer, port, sysid, "FENCE_ACTION", 1.0)
      assert Task.await(task) == {:ok, 1.0}

      # A refusal is another value in answer to two sendings (one alone may
      # be an older PARAM_VALUE come late): the vehicle answers each with the value it keeps.
      task = Task.async(fn -> Vehicles.set_param(sysid, "FENCE_ALT_MAX", 5000, ack_timeout_ms: 200, attempts: 5) end)

      for _ <- 1..2 do
        UDPPeer.receive_until(peer, &match?(%M.ParamSet{param_id: "FENCE_ALT_MAX"}, &1.message))
        param_value(peer, port, sysid, "FENCE_ALT_MAX", 1000.0)
      end

      assert {:error, %Dolphin.ParamError{result: :refused, kept: 1000.0} = e} = Task.await(task, 30_000)
      assert Exception.message(e) == "vehicle #{sysid} kept FENCE_ALT_MAX at 1000 when asked for 5000"

      task = Task.async(fn -> Vehicles.read_param(sysid, "FENCE_ENABLE", @one_attempt) end)
      assert %M.ParamRequestRead{param_id: "FENCE_ENABLE", param_index: -1} = UDPPeer.receive_until(peer, &match?(%M.ParamRequestRead{}, &1.message)).message
      param_value(peer, port, sysid, "FENCE_ENABLE", 0.0)
      assert Task.await(task) == {:ok, 0.0}
    end

    test "no answer: sent again, then a timeout naming the parameter", %{peer: peer, sysid: sysid} do
      assert {:error, %Dolphin.ParamError{result: :timeout, attempts: 2} = e} = Vehicles.set_param(sysid, "NO_SUCH_PARAM", 3, attempts: 2)
      assert Exception.message(e) == "vehicle #{sysid} did not answer for parameter NO_SUCH_PARAM (2 attempts)"
      for _ <- 1..2, do: assert(%M.ParamSet{param_id: "NO_SUCH_PARAM"} = UDPPeer.receive_until(peer, &match?(%M.ParamSet{}, &1.message)).message)
    end
  end

  test "two commands with one id run one after the other", %{peer: peer, port: port, sysid: sysid} do
    t1 = Task.async(fn -> Vehicles.set_message_interval(sysid, 33, 100_000, @one_attempt) end)
    # (Past any copy of the vehicle process's own interval requests a busy machine left in the socket.)
    assert %M.CommandLong{param1: 33.0} = UDPPeer.receive_until(peer, &match?(%M.CommandLong{command: 511, param1: 33.0}, &1.message)).message
    t2 = Task.async(fn -> Vehicles.set_message_interval(sysid, 30, 50_000, @one_attempt) end)
    Process.sleep(300)
    ack(peer, port, sysid, 511, 0)
    assert Task.await(t1) == {:ok, :accepted}
    assert %M.CommandLong{param1: 30.0} = UDPPeer.receive_until(peer, &match?(%M.CommandLong{command: 511, param1: 30.0}, &1.message)).message
    ack(peer, port, sysid, 511, 2)
    assert {:error, %CommandError{result: :denied}} = Task.await(t2)
  end

  test "modes by name; a mode the vehicle does not have is refused before anything is sent", %{peer: peer, port: port, sysid: sysid} do
    task = Task.async(fn -> Vehicles.set_mode(sysid, :brake, @one_attempt) end)
    assert %M.CommandLong{param1: 1.0, param2: 17.0} = next_command(peer, 176)
    ack(peer, port, sysid, 176, 0)
    assert Task.await(task) == {:ok, :accepted}

    assert {:error, %CommandError{result: :not_sent} = e} = Vehicles.set_mode(sysid, :warp)
    assert Exception.message(e) =~ "MAV_CMD_DO_SET_MODE not sent to vehicle #{sysid} (no mode :warp on this vehicle"
  end

  test "COMMAND_INT carries the position as integers", %{peer: peer, port: port, sysid: sysid} do
    task = Task.async(fn -> Vehicles.command_int(sysid, :mav_cmd_do_reposition, [-1], {41.178, -8.596, 30}, @one_attempt) end)
    %M.CommandInt{x: 411_780_000, y: -85_960_000, z: 30.0, frame: 6, param1: -1.0} = UDPPeer.receive_until(peer, &match?(%M.CommandInt{}, &1.message)).message

    ack(peer, port, sysid, 192, 0)
    assert Task.await(task) == {:ok, :accepted}

    home = Task.async(fn -> Vehicles.set_home(sysid, {41.1780001, -8.5960001, 110.5}, @one_attempt) end)
    %M.CommandInt{command: 179, frame: 0, x: 411_780_001, y: -85_960_001, z: 110.5} = UDPPeer.receive_until(peer, &match?(%M.CommandInt{command: 179}, &1.message)).message

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
    t1 = Task.async(fn -> Vehicles.arm(sysid, @one_attempt) end)
    next_command(peer, 400)
    instance = Dolphin.Instance.current()

    {pid, ref} =
      spawn_monitor(fn ->
        Dolphin.Instance.put(instance)
        Vehicles.command(sysid, 400, [4])
      end)

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

  # The protocol hands each message to the link (a cast) before it reports
  # progress; a call to the link afterwards returns once the link has sent them
  # all, so everything sent so far is in the peer's socket and no wait is needed.
  defp drain(peer, link) do
    Connection.port(link)
    drain_socket(peer)
  end

  defp drain_socket(peer) do
    case :gen_udp.recv(peer, 0, 0) do
      {:ok, _} -> drain_socket(peer)
      {:error, :timeout} -> :ok
    end
  end

  defp refute_command(peer, command) do
    assert_raise ExUnit.AssertionError, fn -> next_command(peer, command, 100) end
  end
end
