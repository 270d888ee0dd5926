defmodule Dolphin.Link.ConnectionTest do
  # Real sockets on 127.0.0.1: a TCP "vehicle" server, a QGroundControl stand-in
  # for forwarding, a signing peer. Shares the vehicle registry: not async.
  use ExUnit.Case, async: false

  # The TCP test drops the connection on purpose: its warnings are expected.
  @moduletag :capture_log

  alias Dolphin.Test.Wait

  alias Dolphin.{Link, Vehicles}
  alias Dolphin.Link.Connection
  alias Dolphin.MAVLink.{Frame, Parser, Signing}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Test.UDPPeer

  defp copter, do: %M.Heartbeat{type: 2, autopilot: 3, custom_mode: 4, base_mode: 0x81}

  defp cleanup(link, sysids) do
    on_exit(fn ->
      DynamicSupervisor.terminate_child(Dolphin.Link.Supervisor, link)
      Enum.each(sysids, &Vehicles.forget/1)
    end)
  end

  test "tcp: frames split anywhere are reassembled, and the link reconnects when the server drops it" do
    {:ok, listen} = :gen_tcp.listen(0, [:binary, active: false, ip: {127, 0, 0, 1}, reuseaddr: true])
    {:ok, port} = :inet.port(listen)
    {:ok, link} = Link.connect("tcp:127.0.0.1:#{port}", name: "tcp-test")
    cleanup(link, [41])
    # A read's frames are decoded in a young heap made for them (rounded up to a heap size).
    {:min_heap_size, words} = Process.info(link, :min_heap_size)
    assert words >= Connection.spawn_opt()[:min_heap_size]

    {:ok, conn} = :gen_tcp.accept(listen, 30_000)
    bytes = Frame.encode(copter(), sysid: 41, compid: 1) <> Frame.encode(%M.SysStatus{battery_remaining: 66}, sysid: 41, compid: 1, seq: 1)
    # Three writes that cut both frames in the middle.
    for part <- [binary_part(bytes, 0, 7), binary_part(bytes, 7, 20), binary_part(bytes, 27, byte_size(bytes) - 27)] do
      :ok = :gen_tcp.send(conn, part)
      Process.sleep(5)
    end

    Wait.until(fn -> match?({:ok, %{battery: 0.66, mode: :guided}}, Vehicles.state(41)) end)
    # The ground station answers over the same connection (its heartbeat, telemetry requests).
    assert {:ok, data} = :gen_tcp.recv(conn, 0, 30_000)
    {frames, _} = Parser.feed(Parser.new(), data)
    assert Enum.any?(frames, &(&1.sysid == 255))

    :gen_tcp.close(conn)
    # Backoff starts at 0.5 s: the link is back within a few seconds.
    {:ok, conn2} = :gen_tcp.accept(listen, 30_000)
    assert Connection.info("tcp-test").connected
    :gen_tcp.close(conn2)
    :gen_tcp.close(listen)
  end

  test "datagrams waiting for a busy link reach their vehicle in one message, in order, each applied" do
    name = "batch-#{System.unique_integer([:positive])}"
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: name)
    cleanup(link, [23, 24])
    port = Connection.port(name)
    peer = UDPPeer.open()
    send_bytes = fn bytes -> :ok = :gen_udp.send(peer, {127, 0, 0, 1}, port, bytes) end

    for sysid <- [23, 24], do: send_bytes.(Frame.encode(copter(), sysid: sysid, compid: 1))
    Wait.until(fn -> match?({:ok, _}, Vehicles.state(23)) and match?({:ok, _}, Vehicles.state(24)) end)
    vehicle = Vehicles.whereis_local(23)
    :erlang.trace(vehicle, true, [:receive])

    # The link busy: what comes meanwhile waits in its mailbox.
    :ok = :sys.suspend(link)
    for {battery, seq} <- Enum.with_index([90, 80, 70, 60], 1), do: send_bytes.(Frame.encode(%M.SysStatus{battery_remaining: battery}, sysid: 23, compid: 1, seq: seq))
    send_bytes.(Frame.encode(%M.SysStatus{battery_remaining: 10}, sysid: 24, compid: 1, seq: 1))
    send_bytes.(Frame.encode(%M.SysStatus{battery_remaining: 50}, sysid: 23, compid: 1, seq: 5))
    Wait.until(fn -> Process.info(link, :message_queue_len) == {:message_queue_len, 6} end)
    :ok = :sys.resume(link)

    assert_receive {:trace, ^vehicle, :receive, {:"$gen_cast", {:frames, frames}}}, 5_000
    assert Enum.map(frames, fn {frame, _via} -> frame.message.battery_remaining end) == [90, 80, 70, 60, 50]
    :erlang.trace(vehicle, false, [:receive])
    Wait.until(fn -> match?({:ok, %{battery: 0.5}}, Vehicles.state(23)) and match?({:ok, %{battery: 0.1}}, Vehicles.state(24)) end)
    assert %{stats: %{frames: 8}} = Connection.info(name)
  end

  test "a router given is called for each frame, whatever it returns" do
    name = "router-#{System.unique_integer([:positive])}"
    me = self()
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: name, router: fn frame, _via -> send(me, {:routed, frame.seq}) && nil end)
    cleanup(link, [])
    peer = UDPPeer.open()
    for seq <- [1, 2], do: :ok = :gen_udp.send(peer, {127, 0, 0, 1}, Connection.port(name), Frame.encode(copter(), sysid: 25, compid: 1, seq: seq))
    assert_receive {:routed, 1}, 5_000
    assert_receive {:routed, 2}, 5_000
    # Still the same link, which counted both (a call: after it has handled them).
    assert %{stats: %{frames: 2}} = Connection.info(name)
    assert Process.alive?(link)
  end

  @tag :tmp_dir
  test "two links recording to one .tlog record a frame heard on both once, and a frame heard twice on one link twice", %{tmp_dir: dir} do
    tlog = Path.join(dir, "shared.tlog")
    names = for _ <- 1..2, do: "tlog-#{System.unique_integer([:positive])}"
    links = for name <- names, do: elem(Link.connect("udpin:127.0.0.1:0", name: name, tlog: tlog), 1)
    for link <- links, do: cleanup(link, [21])
    [a, b] = Enum.map(names, &Connection.port/1)
    peer = UDPPeer.open()

    send_bytes = fn port, bytes -> :ok = :gen_udp.send(peer, {127, 0, 0, 1}, port, bytes) end
    # One frame heard on both links (two radios); another heard twice on one (a reboot, a wrap).
    both = Frame.encode(copter(), sysid: 21, compid: 1, seq: 7)
    twice = Frame.encode(%M.SysStatus{battery_remaining: 50}, sysid: 21, compid: 1, seq: 8)
    send_bytes.(a, both)
    Wait.until(fn -> match?(%{stats: %{frames: 1}}, Connection.info(Enum.at(names, 0))) end)
    send_bytes.(b, both)
    send_bytes.(b, twice)
    send_bytes.(b, twice)
    # Each link counts what it received.
    Wait.until(fn -> match?(%{stats: %{frames: 3}}, Connection.info(Enum.at(names, 1))) end)

    for link <- links, do: :ok = DynamicSupervisor.terminate_child(Dolphin.Link.Supervisor, link)
    {records, _} = Dolphin.MAVLink.Tlog.read(Dolphin.MAVLink.Tlog.reader(), File.read!(tlog))
    heard = for {_ts, %Frame{sysid: 21} = f} <- records, do: f.raw
    assert Enum.frequencies(heard) == %{both => 1, twice => 2}
  end

  @tag :tmp_dir
  test "a link that stopped is no copy source: the next link on the file records the very same frames", %{tmp_dir: dir} do
    tlog = Path.join(dir, "again.tlog")
    peer = UDPPeer.open()
    frame = Frame.encode(copter(), sysid: 22, compid: 1, seq: 3)

    # One run, then the next at once, sending the same bytes (a deterministic simulation).
    for round <- 1..2 do
      name = "again-#{round}"
      {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: name, tlog: tlog)
      cleanup(link, [22])
      :ok = :gen_udp.send(peer, {127, 0, 0, 1}, Connection.port(name), frame)
      Wait.until(fn -> match?(%{stats: %{frames: 1}}, Connection.info(name)) end)
      :ok = Link.disconnect(link)
    end

    {records, _} = Dolphin.MAVLink.Tlog.read(Dolphin.MAVLink.Tlog.reader(), File.read!(tlog))
    assert length(for {_ts, %Frame{sysid: 22}} <- records, do: 1) == 2
  end

  test "forwarding: a watcher gets all traffic, both ways" do
    watcher = UDPPeer.open()
    {:ok, watcher_port} = :inet.port(watcher)
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: "fwd-test", forward: ["udpout:127.0.0.1:#{watcher_port}"])
    cleanup(link, [42])
    peer = UDPPeer.open()
    UDPPeer.send_message(peer, Connection.port("fwd-test"), copter(), sysid: 42)

    assert %Frame{sysid: 42} = UDPPeer.receive_until(watcher, &(&1.sysid == 42))
    assert %Frame{sysid: 255} = UDPPeer.receive_until(watcher, &(&1.sysid == 255))
  end

  test "signing: with require, unsigned frames are dropped; what the link sends is signed" do
    key = :crypto.hash(:sha256, "fleet key")
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: "sign-test", signing: [key: key, link_id: 7, require: true])
    cleanup(link, [43, 44])
    port = Connection.port("sign-test")
    peer = UDPPeer.open()

    UDPPeer.send_message(peer, port, copter(), sysid: 43)
    Wait.until(fn -> Connection.info("sign-test").stats.unsigned == 1 end)
    assert Vehicles.whereis(43) == nil

    {bytes, _} = Signing.encode(Signing.new(key: key, link_id: 3), copter(), sysid: 44, compid: 1)
    :ok = :gen_udp.send(peer, {127, 0, 0, 1}, port, bytes)
    Wait.until(fn -> Vehicles.whereis(44) end)

    heartbeat = UDPPeer.receive_until(peer, &match?(%M.Heartbeat{type: 6}, &1.message))
    assert %{link_id: 7} = heartbeat.signature
    assert {:ok, _} = Signing.verify(Signing.new(key: key), heartbeat)
  end

  test "a stopped link has closed its sockets itself: its port can be opened again at once" do
    port = Dolphin.Test.GroundStation.free_udp_port()
    {:ok, link} = Link.connect("udpin:127.0.0.1:#{port}", name: "close-test", forward: ["udpout:127.0.0.1:9"])
    cleanup(link, [])
    # The listening socket and the forwarding one.
    {:links, linked} = Process.info(link, :links)
    sockets = for p <- linked, is_port(p), do: {Port.monitor(p), p}
    assert length(sockets) == 2

    :ok = Link.disconnect(link)
    # Closed by the link (reason :normal), not by its exit (the exit's reason,
    # a moment after the exit: a port opened again at once could still be taken).
    for {ref, socket} <- sockets, do: assert_receive({:DOWN, ^ref, :port, ^socket, :normal}, 30_000)
    assert {:ok, again} = :gen_udp.open(port, ip: {127, 0, 0, 1})
    :gen_udp.close(again)
  end

  @tag :tmp_dir
  test "a telemetry log that cannot be written: no link, and why in words", %{tmp_dir: dir} do
    tlog = Path.join([dir, "missing", "run.tlog"])
    assert {:error, e} = Link.connect("udpin:127.0.0.1:0", name: "tlog-missing", tlog: tlog)
    assert Exception.message(e) == "udpin:127.0.0.1:0: cannot open: telemetry log #{tlog}: no such file or directory"
    assert Registry.lookup(Dolphin.Registry, {:link, "tlog-missing"}) == []
  end
end
