defmodule Dolphin.VehiclesTest do
  # A scripted MAVLink peer talks to a real UDP link on 127.0.0.1. Its own
  # Dolphin.Instance (its vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.Test.Wait

  alias Dolphin.{Clock, Link, Vehicles}
  alias Dolphin.Vehicles.View
  alias Dolphin.Link.Connection
  alias Dolphin.MAVLink.{Frame, Tlog}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Test.UDPPeer

  @moduletag :tmp_dir

  setup %{tmp_dir: dir} do
    name = "test-#{System.unique_integer([:positive])}"
    tlog = Path.join(dir, "link.tlog")
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: name, tlog: tlog)
    port = Connection.port(name)
    peer = UDPPeer.open()

    Dolphin.Test.Instance.on_exit(fn ->
      Clock.set_speedup(1)
      DynamicSupervisor.terminate_child(Dolphin.Instance.names().links, link)
      Enum.each(Vehicles.list(), &Vehicles.forget/1)
    end)

    %{name: name, port: port, peer: peer, tlog: tlog}
  end

  defp copter(mode \\ 4), do: %M.Heartbeat{type: 2, autopilot: 3, base_mode: 0x81, custom_mode: mode, system_status: 4}

  test "a vehicle heard on one udpin link from two addresses (a radio and a relay) has two paths, and is sent to on the one in use",
       %{port: port, peer: peer, name: name} do
    relay = UDPPeer.open()
    Vehicles.subscribe(:all)
    # The same frame from both: one vehicle, the frame applied once.
    heartbeat = Frame.encode(copter(), sysid: 12, compid: 1, seq: 0)
    :ok = :gen_udp.send(peer, {127, 0, 0, 1}, port, heartbeat)
    assert_receive {:dolphin, :vehicles, {:vehicle_discovered, 12}}, 10_000
    :ok = :gen_udp.send(relay, {127, 0, 0, 1}, port, heartbeat)
    Wait.until(fn -> length(Vehicles.paths(12)) == 2 end)

    {:ok, radio_port} = :inet.port(peer)
    {:ok, relay_port} = :inet.port(relay)
    assert [%{via: {^name, {_, ^radio_port}}, in_use?: true, frames: 1}, %{via: {^name, {_, ^relay_port}}, in_use?: false, frames: 1}] = Vehicles.paths(12)
    assert {:ok, %{link: %{received: 1}}} = Vehicles.state(12)

    # The relay's path is the vehicle's once its autopilot and the radio's
    # report one unique id (asked on both).
    assert [%{identity: :same}, %{identity: :pending}] = Vehicles.paths(12)

    for socket <- [peer, relay] do
      UDPPeer.receive_until(socket, &match?(%M.CommandLong{command: 520, target_system: 12}, &1.message), 10_000)
      UDPPeer.send_message(socket, port, %M.AutopilotVersion{uid: 7}, sysid: 12)
    end

    Wait.until(fn -> match?([%{identity: :same, uid: 7}, %{identity: :same, uid: 7}], Vehicles.paths(12)) end)
    assert {:ok, %{uid: 7}} = Vehicles.view(12)

    :ok = Vehicles.send_message(12, %M.Statustext{severity: 6, text: "to the path in use"})
    assert %Frame{} = UDPPeer.receive_until(peer, &match?(%M.Statustext{}, &1.message), 10_000)
    # Sent once, by the same link just before: a copy to the relay would be there by now.
    assert_raise ExUnit.AssertionError, fn -> UDPPeer.receive_until(relay, &match?(%M.Statustext{}, &1.message), 300) end
  end

  test "another vehicle with the same system id on another address is another vehicle, never merged", %{port: port, peer: peer} do
    other = UDPPeer.open()
    Vehicles.subscribe(:all)
    Dolphin.Events.subscribe()
    UDPPeer.send_message(peer, port, copter(4), sysid: 12)
    assert_receive {:dolphin, :vehicles, {:vehicle_discovered, 12}}, 10_000
    # Another copter, in LOITER, also system id 12 (both left the factory so).
    UDPPeer.send_message(other, port, copter(5), sysid: 12)

    # Each answers the question of its identity with its own unique id.
    for {socket, uid} <- [{peer, 7}, {other, 9}] do
      UDPPeer.receive_until(socket, &match?(%M.CommandLong{command: 520}, &1.message), 10_000)
      UDPPeer.send_message(socket, port, %M.AutopilotVersion{uid: uid}, sysid: 12, seq: 1)
    end

    {:ok, other_port} = :inet.port(other)
    name = "12@127.0.0.1:#{other_port}"
    Dolphin.Test.Instance.on_exit(fn -> Vehicles.forget(name) end)
    assert_receive {:dolphin, :events, %{event: :system_id_shared, vehicle: 12, uid: 9, vehicle_uid: 7, path: path, other: ^name} = event}, 10_000
    assert path =~ "from 127.0.0.1:#{other_port}"
    assert Dolphin.EventText.event_text(event) =~ "vehicle 12: another vehicle with its system id is heard on #{path} (unique id 9, not 7): that is vehicle #{name}"

    # Nothing of the other is taken for the vehicle; the other is a vehicle
    # of its own from its next heartbeat, named by the address it sends from.
    UDPPeer.send_message(other, port, copter(5), sysid: 12, seq: 2)
    assert_receive {:dolphin, :vehicles, {:vehicle_discovered, ^name}}, 10_000
    UDPPeer.send_message(other, port, %M.SysStatus{battery_remaining: 90}, sysid: 12, seq: 3)
    UDPPeer.send_message(peer, port, %M.SysStatus{battery_remaining: 40}, sysid: 12, seq: 2)
    Wait.until(fn -> match?({:ok, %{battery: 0.4}}, Vehicles.view(12)) end)
    Wait.until(fn -> match?({:ok, %{battery: 0.9}}, Vehicles.view(name)) end)
    assert {:ok, %{mode: :guided, uid: 7, battery: 0.4, network: "127.0.0.1:" <> _}} = Vehicles.view(12)
    assert {:ok, %{mode: :loiter, battery: 0.9, network: network}} = Vehicles.view(name)
    assert network == "127.0.0.1:#{other_port}"
    assert [%{in_use?: true, identity: :same}, %{identity: :refused, uid: 9, frames: 2}] = Vehicles.paths(12)

    # Each is sent what is meant for it, and nothing else.
    :ok = Vehicles.send_message(12, %M.Statustext{severity: 6, text: "to the vehicle"})
    assert %Frame{} = UDPPeer.receive_until(peer, &match?(%M.Statustext{text: "to the vehicle"}, &1.message), 10_000)
    assert_raise ExUnit.AssertionError, fn -> UDPPeer.receive_until(other, &match?(%M.Statustext{text: "to the vehicle"}, &1.message), 300) end
    :ok = Vehicles.send_message(name, %M.Statustext{severity: 6, text: "to the other"})
    assert %Frame{} = UDPPeer.receive_until(other, &match?(%M.Statustext{text: "to the other"}, &1.message), 10_000)
    assert_raise ExUnit.AssertionError, fn -> UDPPeer.receive_until(peer, &match?(%M.Statustext{text: "to the other"}, &1.message), 300) end

    # The ground station's heartbeat reaches both (their GCS failsafes need it).
    for socket <- [peer, other], do: assert(%Frame{} = UDPPeer.receive_until(socket, &match?(%M.Heartbeat{type: 6}, &1.message), 10_000))
  end

  test "a forgotten vehicle is gone at once, and heard again it is discovered anew", %{port: port, peer: peer} do
    Vehicles.subscribe(:all)

    for round <- 1..20 do
      UDPPeer.send_message(peer, port, copter(), sysid: 13)
      assert_receive {:dolphin, :vehicles, {:vehicle_discovered, 13}}, 10_000
      pid = Vehicles.whereis(13)
      :ok = Vehicles.forget(13)
      # No moment in which the stopped process is still given for it.
      refute Vehicles.whereis(13), "round #{round}: #{inspect(pid)} still given after forget"
      refute Process.alive?(pid)
    end
  end

  test "a vehicle is discovered from its heartbeat, asked for telemetry, and sent the GCS heartbeat", %{port: port, peer: peer} do
    Vehicles.subscribe(:all)
    UDPPeer.send_message(peer, port, copter(), sysid: 11)
    assert_receive {:dolphin, :vehicles, {:vehicle_discovered, 11}}, 10_000
    assert 11 in Vehicles.list()

    # What ArduPilot needs to start streaming: REQUEST_DATA_STREAM and SET_MESSAGE_INTERVAL.
    assert %Frame{sysid: 255, message: %M.RequestDataStream{target_system: 11, start_stop: 1}} = UDPPeer.receive_until(peer, &match?(%M.RequestDataStream{}, &1.message))

    # The message intervals come one at a time, each once the previous one is
    # answered (as ArduPilot does, with COMMAND_ACK accepted).
    asked =
      Enum.map(1..6, fn _ ->
        %Frame{message: %M.CommandLong{param1: msgid}} = UDPPeer.receive_until(peer, &match?(%M.CommandLong{command: 511}, &1.message))
        UDPPeer.send_message(peer, port, %M.CommandAck{command: 511, result: 0, target_system: 255}, sysid: 11)
        trunc(msgid)
      end)

    # GLOBAL_POSITION_INT, SYS_STATUS, BATTERY_STATUS, MISSION_CURRENT, EXTENDED_SYS_STATE, HOME_POSITION
    assert asked == [33, 1, 147, 42, 245, 242]

    assert %Frame{sysid: 255, compid: 190, message: %M.Heartbeat{type: 6, autopilot: 8}} = UDPPeer.receive_until(peer, &match?(%M.Heartbeat{}, &1.message))

    {:ok, state} = Vehicles.state(11)
    assert {state.mode, state.armed, state.autopilot} == {:guided, true, :ardupilot}
    assert {:ok, %{connected?: true}} = Vehicles.view(11)
  end

  test "each change of a vehicle's view is published to its subscribers, whole", %{port: port, peer: peer} do
    UDPPeer.send_message(peer, port, copter(), sysid: 12)
    Wait.until(fn -> Vehicles.whereis(12) end)
    Vehicles.subscribe(12)

    UDPPeer.send_message(peer, port, %M.SysStatus{battery_remaining: 55}, sysid: 12, seq: 1)
    assert_receive {:dolphin, {:vehicle, 12}, {:view, %View{id: 12, battery: 0.55, position: nil}}}, 10_000

    UDPPeer.send_message(peer, port, %M.GlobalPositionInt{lat: 411_780_000, lon: -85_960_000, relative_alt: 10_000}, sysid: 12, seq: 2)
    assert_receive {:dolphin, {:vehicle, 12}, {:view, %View{battery: 0.55, position: %{lat: 41.178}, relative_altitude: 10.0}}}, 10_000

    # What the autopilot says is in the view, for readers that report it.
    before = Vehicles.status_texts(12)
    UDPPeer.send_message(peer, port, %M.Statustext{severity: 4, text: "PreArm: Need Position Estimate"}, sysid: 12, seq: 3)
    assert_receive {:dolphin, {:vehicle, 12}, {:view, %View{status_texts: [{4, "PreArm: Need Position Estimate"} | _]} = view}}, 10_000
    assert {view.mav_type, view.autopilot, view.type} == {2, :ardupilot, :uav}
    assert Dolphin.Vehicles.State.texts_since(before, Vehicles.status_texts(12)) == [{4, "PreArm: Need Position Estimate"}]

    # A GCS's heartbeat (another ground station on the link) is not a vehicle.
    UDPPeer.send_message(peer, port, %M.Heartbeat{type: 6, autopilot: 8}, sysid: 250)
    UDPPeer.send_message(peer, port, copter(), sysid: 12, seq: 4)
    Wait.until(fn -> match?({:ok, %{link: %{received: 5}}}, Vehicles.state(12)) end)
    refute 250 in Vehicles.list()
    assert {:error, :unknown_vehicle} = Vehicles.state(250)

    # When it was last heard is read without a call, as its state says it.
    {:ok, state} = Vehicles.state(12)
    assert Dolphin.Vehicles.Views.last_heard_ms(12) == state.link.last_seen_ms
    assert Dolphin.Vehicles.Views.last_heard_ms(250) == nil
    :ok = Vehicles.forget(12)
    assert Dolphin.Vehicles.Views.last_heard_ms(12) == nil
  end

  test "a silent vehicle is lost after its timeout in clock time, and reconnects when heard", %{port: port, peer: peer} do
    Vehicles.subscribe(:all)
    UDPPeer.send_message(peer, port, copter(), sysid: 13)
    assert_receive {:dolphin, :vehicles, {:vehicle_discovered, 13}}, 10_000
    # 20 s of clock time at 200x is 100 ms of real time, but a sped-up
    # vehicle is lost after at least min(timeout, 3 s) of real time: 3 s.
    Clock.set_speedup(200)
    assert_receive {:dolphin, :vehicles, {:vehicle_lost, 13}}, 10_000
    assert {:ok, %{connected?: false}} = Vehicles.view(13)

    UDPPeer.send_message(peer, port, copter(5), sysid: 13, seq: 1)
    assert_receive {:dolphin, :vehicles, {:vehicle_reconnected, 13}}, 10_000
    assert {:ok, %{connected?: true, mode: :loiter}} = Vehicles.view(13)
  end

  test "payloads given to a vehicle (a fleet file's) are in its view from its first one, and a change shows at once", %{port: port, peer: peer} do
    :ok = Vehicles.put_payloads(19, [:sidescan])
    Vehicles.subscribe(19)
    UDPPeer.send_message(peer, port, copter(), sysid: 19)
    assert_receive {:dolphin, {:vehicle, 19}, {:view, %{payloads: [:sidescan], airframe: :copter}}}, 10_000
    :ok = Vehicles.put_payloads(19, [:smoke, :sidescan, :smoke])
    assert_receive {:dolphin, {:vehicle, 19}, {:view, %{payloads: [:sidescan, :smoke]}}}, 10_000
    assert Vehicles.given_payloads(19) == [:sidescan, :smoke]
    assert_raise ArgumentError, ~r/payloads are atoms/, fn -> Vehicles.put_payloads(19, ["sonar"]) end
  end

  test "a timeout set for a vehicle is checked at its own pace from then on, not at the old one's", %{port: port, peer: peer} do
    UDPPeer.send_message(peer, port, copter(), sysid: 18)
    pid = Wait.until(fn -> Vehicles.whereis(18) end)
    # The default timeout (20 s of clock time) is checked every 2 s.
    :ok = Vehicles.set_timeout(18, 1_000)
    s = :sys.get_state(pid)
    assert s.timeout_ms == 1_000
    # Its silence is now looked at every 100 ms of clock time (here 1x); the
    # timer may have fired since its state was read (false), on a loaded host.
    remaining = Process.read_timer(s.check_timer)
    assert remaining == false or remaining <= 100
    assert s.check_due_ms - Clock.now_ms() <= 100
  end

  test "a restarted vehicle process is lost when silent, and keeps the timeout set for it", %{port: port, peer: peer} do
    Vehicles.subscribe(:all)
    UDPPeer.send_message(peer, port, copter(), sysid: 16)
    pid = Wait.until(fn -> Vehicles.whereis(16) end)
    :ok = Vehicles.set_timeout(16, 1_000)
    Process.exit(pid, :kill)
    Wait.until(fn -> (p = Vehicles.whereis(16)) != pid && p end)
    assert_receive {:dolphin, :vehicles, {:vehicle_lost, 16}}, 10_000
  end

  test "a pause of the ground station itself is not the vehicle's silence", %{name: name, port: port, peer: peer} do
    Vehicles.subscribe(:all)
    # Set before discovery (kept for the process to come), so that its checks
    # come every 300 ms from the start.
    {:error, :unknown_vehicle} = Vehicles.set_timeout(17, 3_000)
    UDPPeer.send_message(peer, port, copter(), sysid: 17)
    assert_receive {:dolphin, :vehicles, {:vehicle_discovered, 17}}, 10_000
    Wait.until(fn -> match?({:ok, %{link: %{received: 1}}}, Vehicles.state(17)) end)
    vehicle = Vehicles.whereis(17)
    [{link, _}] = Registry.lookup(Dolphin.Instance.names().registry, {:link, name})

    # The whole ground station held up (as a loaded host does) for longer than
    # the timeout and a check period, while the vehicle went on sending: its
    # frame waits for the link. Then the vehicle's process runs first, its
    # silence check late.
    true = :erlang.suspend_process(link)
    true = :erlang.suspend_process(vehicle)
    UDPPeer.send_message(peer, port, copter(), sysid: 17, seq: 1)
    Clock.sleep(4_500)
    true = :erlang.resume_process(vehicle)
    assert {:ok, %{connected?: true}} = Vehicles.view(17)
    true = :erlang.resume_process(link)
    Wait.until(fn -> match?({:ok, %{link: %{received: 2}}}, Vehicles.state(17)) end)
    refute_received {:dolphin, :vehicles, {:vehicle_lost, 17}}

    # Real silence is still silence.
    assert_receive {:dolphin, :vehicles, {:vehicle_lost, 17}}, 10_000
  end

  test "a silence that began at a higher speed-up is judged by real time's floor, not by the clock time run up before the clock slowed", %{port: port, peer: peer} do
    Vehicles.subscribe(:all)
    Clock.set_speedup(100)
    UDPPeer.send_message(peer, port, copter(), sysid: 11)
    assert_receive {:dolphin, :vehicles, {:vehicle_discovered, 11}}, 10_000
    vehicle = Vehicles.whereis(11)

    # Silent for 0.5 s of real time at 100x (50 s of clock time, past the
    # 20 s timeout, within the 5 s floor), then the clock slows to 1x, as
    # it follows a SITL vehicle that fell behind: at 1x the floor is the
    # timeout, which the clock time run up at 100x already passes.
    Process.sleep(500)
    Clock.set_speedup(1)
    slowed = Clock.now_ms()
    # A check after the change (each sets the next one a period, 2 s of clock time, ahead).
    Wait.until(fn -> :sys.get_state(vehicle).check_due_ms > slowed + 2_000 end)
    refute :sys.get_state(vehicle).lost
    refute_received {:dolphin, :vehicles, {:vehicle_lost, 11}}
  end

  test "a frame waiting in the vehicle's mailbox behind its silence check ends the silence: not lost", %{port: port, peer: peer} do
    Vehicles.subscribe(:all)
    # Set before discovery (kept for the process to come): its silence limit is 3 s exactly.
    {:error, :unknown_vehicle} = Vehicles.set_timeout(15, 3_000)
    UDPPeer.send_message(peer, port, copter(), sysid: 15)
    assert_receive {:dolphin, :vehicles, {:vehicle_discovered, 15}}, 10_000
    vehicle = Vehicles.whereis(15)

    # Silent, as far as its state says, for ten timeouts; its next check
    # due now and sent by hand (its timer cancelled), so that it runs on time.
    :sys.replace_state(vehicle, fn s ->
      Process.cancel_timer(s.check_timer)
      last = Clock.now_ms() - 30_000
      %{s | check_timer: make_ref(), check_due_ms: Clock.now_ms(), state: %{s.state | link: %{s.state.link | last_seen_ms: last}}}
    end)

    # The process held up while its check and then a frame are queued.
    true = :erlang.suspend_process(vehicle)
    send(vehicle, :check_link)
    UDPPeer.send_message(peer, port, copter(), sysid: 15, seq: 1)
    Wait.until(fn -> match?({:messages, [:check_link, {:"$gen_cast", {:frame, _, _}}]}, Process.info(vehicle, :messages)) end)
    true = :erlang.resume_process(vehicle)

    Wait.until(fn -> match?({:ok, %{link: %{received: 2}}}, Vehicles.state(15)) end)
    assert {:ok, %{connected?: true}} = Vehicles.view(15)
    refute_received {:dolphin, :vehicles, {:vehicle_lost, 15}}
  end

  test "a crashed vehicle process is restarted and rebuilt from the next telemetry; a crashed link loses no vehicle",
       %{name: name, port: port, peer: peer} do
    UDPPeer.send_message(peer, port, copter(), sysid: 14)
    pid = Wait.until(fn -> Vehicles.whereis(14) end)
    Process.exit(pid, :kill)
    new_pid = Wait.until(fn -> (p = Vehicles.whereis(14)) != pid && p end)
    assert is_pid(new_pid)
    UDPPeer.send_message(peer, port, copter(17), sysid: 14, seq: 1)
    Wait.until(fn -> match?({:ok, %{mode: :brake}}, Vehicles.state(14)) end)

    [{link, _}] = Registry.lookup(Dolphin.Instance.names().registry, {:link, name})
    Process.exit(link, :kill)
    Wait.until(fn -> match?([{p, _}] when p != link, Registry.lookup(Dolphin.Instance.names().registry, {:link, name})) end)
    assert 14 in Vehicles.list()
  end

  test "every frame in and out is recorded to the .tlog", %{name: name, port: port, peer: peer, tlog: tlog} do
    UDPPeer.send_message(peer, port, copter(), sysid: 15)
    UDPPeer.receive_until(peer, &match?(%M.RequestDataStream{}, &1.message))
    # Stop the link so the file is flushed and closed.
    [{link, _}] = Registry.lookup(Dolphin.Instance.names().registry, {:link, name})
    :ok = DynamicSupervisor.terminate_child(Dolphin.Instance.names().links, link)

    {records, reader} = Tlog.read(Tlog.reader(), File.read!(tlog))
    {[], _} = Tlog.finish(reader)
    senders = records |> Enum.map(fn {_t, f} -> f.sysid end) |> Enum.uniq() |> Enum.sort()
    assert senders == [15, 255]
    assert Enum.any?(records, fn {_t, f} -> match?(%M.RequestDataStream{}, f.message) end)

    # And the reference implementation reads it the same.
    expected = Enum.map(records, fn {_t, f} -> {f.sysid, Dolphin.MAVLink.Message.name(f.message)} end)
    assert Enum.map(Dolphin.Test.Pymavlink.read_tlog(tlog), fn {sysid, type, _ts, _fields} -> {sysid, type} end) == expected
  end

  test "connect reports bad endpoints and busy ports clearly", %{port: port} do
    message = fn {:error, %Link.EndpointError{} = e} -> Exception.message(e) end
    assert "endpoint \"udpin:127.0.0.1\"" <> _ = message.(Link.connect("udpin:127.0.0.1"))
    assert "endpoint \"serial:x:1\"" <> _ = message.(Link.connect("udpin:127.0.0.1:0", name: "fwd", forward: ["serial:x:1"]))
    assert "udpin:127.0.0.1:0: cannot open: can only forward to udpout endpoints, not udpin:127.0.0.1:9" = message.(Link.connect("udpin:127.0.0.1:0", name: "fwd", forward: ["udpin:127.0.0.1:9"]))
    # The setup's link holds `port`.
    assert message.(Link.connect("udpin:127.0.0.1:#{port}", name: "busy")) == "udpin:127.0.0.1:#{port}: cannot open: address already in use"
  end
end
