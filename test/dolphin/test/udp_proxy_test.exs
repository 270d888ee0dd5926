defmodule Dolphin.Test.UDPProxyTest do
  # The impairment proxy (test/support/udp_proxy.ex) over real UDP on
  # 127.0.0.1, with plain sockets as vehicles and ground station. Every wait is
  # on an event (a datagram, a counter); what came through is read up to a
  # marker sent last on a clean link. Each test has its own sockets: async.
  use ExUnit.Case, async: true

  alias Dolphin.Test.{UDPProxy, Wait}

  @localhost {127, 0, 0, 1}
  # Real milliseconds a datagram may take through a loaded machine: a bound on
  # waiting, never a measured duration.
  @patience 5_000

  # An active socket on 127.0.0.1: its datagrams come to the test process as
  # {:udp, socket, ip, port, bytes}. On a loaded machine the runtime can be
  # slow to read it: a default receive buffer (208 KiB) was seen to overflow
  # with a burst of 50 small datagrams, hence 4 MiB (and pacing, below).
  defp open do
    {:ok, socket} = :gen_udp.open(0, [:binary, active: true, ip: @localhost, recbuf: 4 * 1024 * 1024])
    {:ok, port} = :inet.port(socket)
    {socket, port}
  end

  defp proxy(gcs_port, opts \\ []) do
    proxy = start_supervised!({UDPProxy, [gcs: gcs_port] ++ opts}, id: make_ref())
    {proxy, UDPProxy.port(proxy)}
  end

  defp payloads(prefix, n), do: for(i <- 1..n, do: "#{prefix}:#{i}")

  # Sends in batches of 25, each once the proxy has read the last and the
  # receiver has read all the proxy forwarded: a burst of thousands would
  # overflow a kernel receive buffer, and that loss is not the one under test.
  # (Where net.core.rmem_max keeps buffers at 208 KiB, 50 datagrams could.)
  defp send_paced(proxy, dir, {from, to_port}, receiver, payloads) do
    read = fn -> {:ok, [recv_cnt: n]} = :inet.getstat(receiver, [:recv_cnt]); n end
    base = UDPProxy.stats(proxy)[dir]
    read0 = read.()

    payloads
    |> Enum.chunk_every(25)
    |> Enum.reduce(base.received, fn batch, before ->
      Enum.each(batch, &(:ok = :gen_udp.send(from, @localhost, to_port, &1)))
      Wait.until(fn -> UDPProxy.stats(proxy)[dir].received >= before + length(batch) end)
      Wait.until(fn -> read.() - read0 >= UDPProxy.stats(proxy)[dir].forwarded - base.forwarded end)
      before + length(batch)
    end)
  end

  # Until nothing is held back or delayed either way.
  defp settle(proxy), do: Wait.until(fn -> s = UDPProxy.stats(proxy); s.to_gcs.pending == 0 and s.to_vehicle.pending == 0 end)

  # Everything `socket` received before `marker`, sent through a clean link
  # after the proxy settled: on one path, the kernel keeps UDP's order on 127.0.0.1.
  defp through(proxy, dir, {from, to_port}, socket, marker \\ "marker") do
    settle(proxy)
    saved = UDPProxy.stats(proxy).impairments[dir]
    :ok = UDPProxy.set(proxy, [{dir, [loss: 0.0, duplicate: 0.0, reorder: 0.0, latency: 0, jitter: 0]}])
    :ok = :gen_udp.send(from, @localhost, to_port, marker)
    received = collect(socket, marker, [])
    :ok = UDPProxy.set(proxy, [{dir, saved}])
    received
  end

  defp collect(socket, marker, acc) do
    receive do
      {:udp, ^socket, _ip, _port, ^marker} -> Enum.reverse(acc)
      {:udp, ^socket, _ip, _port, bytes} -> collect(socket, marker, [bytes | acc])
    after
      @patience -> flunk("the marker #{inspect(marker)} did not come through; received before it: #{length(acc)}")
    end
  end

  # The ground station learns a vehicle's upstream address from its first datagram.
  defp first_source(socket) do
    assert_receive {:udp, ^socket, @localhost, port, _bytes}, @patience
    port
  end

  describe "a clean link" do
    test "passes everything, in order, both ways, each vehicle from its own socket" do
      {gcs, gcs_port} = open()
      {vehicle, vehicle_port} = open()
      {proxy, port} = proxy(gcs_port)

      :ok = :gen_udp.send(vehicle, @localhost, port, "hello")
      upstream = first_source(gcs)
      assert [{{@localhost, ^vehicle_port}, ^upstream}] = UDPProxy.vehicles(proxy)
      refute upstream in [port, vehicle_port]

      sent = payloads("up", 200)
      send_paced(proxy, :to_gcs, {vehicle, port}, gcs, sent)
      assert through(proxy, :to_gcs, {vehicle, port}, gcs) == sent

      answers = payloads("down", 200)
      send_paced(proxy, :to_vehicle, {gcs, upstream}, vehicle, answers)
      assert through(proxy, :to_vehicle, {gcs, upstream}, vehicle) == answers
      # The answers come from the port the vehicle sends to, as from SITL's ground station.
      :ok = :gen_udp.send(gcs, @localhost, upstream, "from?")
      assert_receive {:udp, ^vehicle, @localhost, ^port, "from?"}, @patience

      settle(proxy)
      s = UDPProxy.stats(proxy)
      assert %{received: 202, forwarded: 202, dropped: 0, duplicated: 0, reordered: 0, pending: 0} = s.to_gcs
      assert %{received: 202, forwarded: 202, dropped: 0, duplicated: 0, reordered: 0, pending: 0} = s.to_vehicle
      assert s.vehicles == 1
    end

    test "answers reach the right vehicle when two share the proxy's port" do
      {gcs, gcs_port} = open()
      {a, a_port} = open()
      {b, b_port} = open()
      {proxy, port} = proxy(gcs_port)

      :ok = :gen_udp.send(a, @localhost, port, "from a")
      assert_receive {:udp, ^gcs, @localhost, a_up, "from a"}, @patience
      :ok = :gen_udp.send(b, @localhost, port, "from b")
      assert_receive {:udp, ^gcs, @localhost, b_up, "from b"}, @patience

      assert a_up != b_up
      assert Enum.sort(UDPProxy.vehicles(proxy)) == Enum.sort([{{@localhost, a_port}, a_up}, {{@localhost, b_port}, b_up}])
      assert UDPProxy.stats(proxy).vehicles == 2

      for i <- 1..20 do
        :ok = :gen_udp.send(gcs, @localhost, a_up, "to a #{i}")
        :ok = :gen_udp.send(gcs, @localhost, b_up, "to b #{i}")
      end

      assert through(proxy, :to_vehicle, {gcs, a_up}, a, "end a") == for(i <- 1..20, do: "to a #{i}")
      assert through(proxy, :to_vehicle, {gcs, b_up}, b, "end b") == for(i <- 1..20, do: "to b #{i}")
    end
  end

  describe "loss" do
    test "at 100 % drops everything each way, and set/2 opens the link again" do
      {gcs, gcs_port} = open()
      {vehicle, _} = open()
      {proxy, port} = proxy(gcs_port)

      # The route back exists once the vehicle has been seen.
      :ok = :gen_udp.send(vehicle, @localhost, port, "hello")
      upstream = first_source(gcs)

      :ok = UDPProxy.set(proxy, both: [loss: 1.0])
      send_paced(proxy, :to_gcs, {vehicle, port}, gcs, payloads("up", 100))
      send_paced(proxy, :to_vehicle, {gcs, upstream}, vehicle, payloads("down", 100))

      :ok = UDPProxy.set(proxy, both: [loss: 0.0])
      assert through(proxy, :to_gcs, {vehicle, port}, gcs) == []
      assert through(proxy, :to_vehicle, {gcs, upstream}, vehicle) == []

      s = UDPProxy.stats(proxy)
      assert %{received: 102, dropped: 100, forwarded: 2} = s.to_gcs
      assert %{received: 101, dropped: 100, forwarded: 1} = s.to_vehicle
    end

    test "at 20 % loses about a fifth of 2,000 datagrams, and only in that direction" do
      {gcs, gcs_port} = open()
      {vehicle, _} = open()
      {proxy, port} = proxy(gcs_port, to_gcs: [loss: 0.2], seed: 11)

      sent = payloads("up", 2_000)
      send_paced(proxy, :to_gcs, {vehicle, port}, gcs, sent)
      got = through(proxy, :to_gcs, {vehicle, port}, gcs)

      # ± 5 points is more than 7 standard deviations at n = 2,000.
      assert length(got) in 1_500..1_700
      # Losing keeps the order of what is left.
      assert got == Enum.filter(sent, &(&1 in MapSet.new(got)))
      s = UDPProxy.stats(proxy)
      assert s.to_gcs.dropped == 2_000 - length(got)
      assert s.impairments.to_vehicle.loss == 0.0
    end
  end

  describe "duplication" do
    test "at 100 % every datagram arrives twice in a row" do
      {gcs, gcs_port} = open()
      {vehicle, _} = open()
      {proxy, port} = proxy(gcs_port, to_gcs: [duplicate: 1.0])

      sent = payloads("up", 100)
      send_paced(proxy, :to_gcs, {vehicle, port}, gcs, sent)
      assert through(proxy, :to_gcs, {vehicle, port}, gcs) == Enum.flat_map(sent, &[&1, &1])
      assert %{received: 101, duplicated: 100, forwarded: 201} = UDPProxy.stats(proxy).to_gcs
    end

    test "at 30 % duplicates about that share, each copy beside its original" do
      {gcs, gcs_port} = open()
      {vehicle, _} = open()
      {proxy, port} = proxy(gcs_port, to_gcs: [duplicate: 0.3], seed: 5)

      sent = payloads("up", 1_000)
      send_paced(proxy, :to_gcs, {vehicle, port}, gcs, sent)
      got = through(proxy, :to_gcs, {vehicle, port}, gcs)

      assert Enum.dedup(got) == sent
      duplicated = length(got) - length(sent)
      assert duplicated in 220..380
      assert UDPProxy.stats(proxy).to_gcs.duplicated == duplicated
    end
  end

  describe "reordering" do
    test "holds datagrams back behind later ones, losing none" do
      {gcs, gcs_port} = open()
      {vehicle, _} = open()
      # A hold long enough that the next datagram (in the same batch) releases it.
      {proxy, port} = proxy(gcs_port, to_gcs: [reorder: 0.3, reorder_ms: @patience], seed: 3)

      sent = payloads("up", 500)
      send_paced(proxy, :to_gcs, {vehicle, port}, gcs, sent)
      # The last may still be held: one more datagram on the same path releases it.
      :ok = UDPProxy.set(proxy, to_gcs: [reorder: 0.0])
      :ok = :gen_udp.send(vehicle, @localhost, port, "last")
      got = through(proxy, :to_gcs, {vehicle, port}, gcs)

      assert Enum.sort(got) == Enum.sort(["last" | sent])
      assert got != sent ++ ["last"]
      reordered = UDPProxy.stats(proxy).to_gcs.reordered
      assert reordered in 100..200
      # Each held datagram comes right after the first one not held after it.
      index = Map.new(Enum.with_index(sent ++ ["last"]))
      positions = Enum.map(got, &index[&1])
      inversions = positions |> Enum.chunk_every(2, 1, :discard) |> Enum.count(fn [a, b] -> a > b end)
      assert inversions > 0 and inversions <= reordered
    end

    test "a held datagram with nothing after it goes out after reorder_ms" do
      {gcs, gcs_port} = open()
      {vehicle, _} = open()
      {proxy, port} = proxy(gcs_port, to_gcs: [reorder: 1.0, reorder_ms: 10])

      :ok = :gen_udp.send(vehicle, @localhost, port, "alone")
      assert_receive {:udp, ^gcs, _, _, "alone"}, @patience
      assert %{reordered: 1, forwarded: 1, pending: 0} = UDPProxy.stats(proxy).to_gcs
    end
  end

  describe "delay" do
    test "a datagram takes at least the latency" do
      {gcs, gcs_port} = open()
      {vehicle, _} = open()
      {proxy, port} = proxy(gcs_port, to_gcs: [latency: 40, jitter: 20])

      sent_at = System.monotonic_time(:millisecond)
      :ok = :gen_udp.send(vehicle, @localhost, port, "slow")
      assert_receive {:udp, ^gcs, _, _, "slow"}, @patience
      # A lower bound only: a loaded machine can make it later, never earlier.
      assert System.monotonic_time(:millisecond) - sent_at >= 40
      settle(proxy)
    end
  end

  test "the same seed and the same datagrams give the same faults; another seed others" do
    run = fn seed ->
      {gcs, gcs_port} = open()
      {vehicle, _} = open()
      {proxy, port} = proxy(gcs_port, seed: seed, to_gcs: [loss: 0.5, duplicate: 0.2, reorder: 0.2, reorder_ms: 5])
      send_paced(proxy, :to_gcs, {vehicle, port}, gcs, payloads("up", 200))
      got = through(proxy, :to_gcs, {vehicle, port}, gcs)
      {Enum.sort(got), Map.take(UDPProxy.stats(proxy).to_gcs, [:dropped, :duplicated, :reordered])}
    end

    assert run.(42) == run.(42)
    assert run.(42) != run.(43)
  end

  test "counters add up each way under every impairment at once" do
    {gcs, gcs_port} = open()
    {vehicle, _} = open()
    {proxy, port} = proxy(gcs_port, seed: 9)

    # A clean first datagram gives the ground station the vehicle's upstream address.
    :ok = :gen_udp.send(vehicle, @localhost, port, "hello")
    upstream = first_source(gcs)
    impairments = [loss: 0.2, duplicate: 0.1, reorder: 0.1, reorder_ms: 5, latency: 2, jitter: 5]
    :ok = UDPProxy.set(proxy, both: impairments)

    send_paced(proxy, :to_gcs, {vehicle, port}, gcs, payloads("up", 300))
    send_paced(proxy, :to_vehicle, {gcs, upstream}, vehicle, payloads("down", 300))
    up = through(proxy, :to_gcs, {vehicle, port}, gcs)
    down = through(proxy, :to_vehicle, {gcs, upstream}, vehicle)

    s = UDPProxy.stats(proxy)

    # What the other end read is all that was forwarded but the marker (and, up, the hello).
    for {dir, got, extra} <- [{:to_gcs, up, 2}, {:to_vehicle, down, 1}] do
      c = s[dir]
      assert c.pending == 0
      assert c.forwarded + c.send_errors == c.received - c.dropped + c.duplicated, "#{dir}: #{inspect(c)}"
      assert length(got) == c.forwarded - extra, "#{dir}: #{inspect(c)}"
      assert c.dropped > 0 and c.duplicated > 0 and c.reordered > 0
    end

    assert s.impairments.to_vehicle == Map.new(impairments)
  end

  describe "lifecycle" do
    test "stopping closes the listening socket and every vehicle's socket" do
      {gcs, gcs_port} = open()
      {vehicle, _} = open()
      {:ok, proxy} = UDPProxy.start_link(gcs: gcs_port)
      port = UDPProxy.port(proxy)
      :ok = :gen_udp.send(vehicle, @localhost, port, "hello")
      upstream = first_source(gcs)

      for p <- [port, upstream], do: assert({:error, :eaddrinuse} = :gen_udp.open(p, ip: @localhost))
      :ok = UDPProxy.stop(proxy)

      for p <- [port, upstream] do
        assert {:ok, s} = :gen_udp.open(p, ip: @localhost)
        :gen_udp.close(s)
      end
    end

    test "stops with its supervisor, or with the process that started it, and closes its sockets" do
      {_gcs, gcs_port} = open()
      proxy = start_supervised!({UDPProxy, gcs: gcs_port})
      port = UDPProxy.port(proxy)
      assert {:error, :eaddrinuse} = :gen_udp.open(port, ip: @localhost)
      :ok = stop_supervised(UDPProxy)
      assert {:ok, s} = :gen_udp.open(port, ip: @localhost)
      :gen_udp.close(s)

      test = self()

      starter =
        spawn(fn ->
          {:ok, proxy} = UDPProxy.start_link(gcs: gcs_port)
          send(test, {:proxy, proxy, UDPProxy.port(proxy)})
          receive do: (:exit -> exit(:shutdown))
        end)

      assert_receive {:proxy, proxy, port}, @patience
      ref = Process.monitor(proxy)
      send(starter, :exit)
      assert_receive {:DOWN, ^ref, :process, ^proxy, :shutdown}, @patience
      assert {:ok, s} = :gen_udp.open(port, ip: @localhost)
      :gen_udp.close(s)
    end

    test "a given port and name are used; bad options are refused, naming what is wrong" do
      {_gcs, gcs_port} = open()
      {free, port} = open()
      :gen_udp.close(free)
      name = :"udp_proxy_#{System.unique_integer([:positive])}"
      {proxy, ^port} = proxy(gcs_port, port: port, name: name)
      assert Process.whereis(name) == proxy and UDPProxy.port(name) == port

      assert_raise ArgumentError, ~r/:gcs option .* is required/, fn -> UDPProxy.start_link([]) end
      assert_raise ArgumentError, ~r/:to_gcs: bad impairment :loss: 1.5/, fn -> UDPProxy.start_link(gcs: gcs_port, to_gcs: [loss: 1.5]) end
      assert_raise ArgumentError, ~r/unknown options \[:lost\]/, fn -> UDPProxy.start_link(gcs: gcs_port, lost: 0.1) end
      {proxy, _} = proxy(gcs_port)
      assert_raise ArgumentError, ~r/:both: bad impairment :latency: -1/, fn -> UDPProxy.set(proxy, both: [latency: -1]) end
      assert_raise ArgumentError, ~r/unknown options \[:gcs\]/, fn -> UDPProxy.set(proxy, gcs: 1) end
    end
  end
end
