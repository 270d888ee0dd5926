defmodule Dolphin.Test.Cluster do
  @moduledoc """
  Ground-station nodes for cluster tests: the test node becomes the
  controller (`ctl<N>@127.0.0.1`, distribution bound to 127.0.0.1), stations
  are `:peer` nodes on 127.0.0.1 with the test's code path, Dolphin started,
  a UDP link on an ephemeral port and simulated vehicles. Every peer is
  stopped and every vehicle forgotten when the test ends.

  Peers are controlled over their standard I/O (`connection: :standard_io`),
  not over distribution: a test can cut the distribution connection
  (`:erlang.disconnect_node/1`, a netsplit) and still drive the peer.
  """

  import ExUnit.Callbacks, only: [on_exit: 1]

  @cookie :dolphin_cluster_test

  @doc """
  A node name of this test VM's cluster: `base` and the VM's OS process id,
  so that two suites running at once on one machine (one EPMD) never take
  each other's names.
  """
  def name(base), do: "#{base}#{System.pid()}"

  @doc "The cookie of the test cluster."
  def cookie, do: @cookie

  @doc """
  A cluster test's set-up: the clock at `speedup`, this node the controller
  (`start_controller/0`), its fleet on the MAVLink vehicles.
  """
  def setup_controller(speedup) do
    Dolphin.Clock.set_speedup(speedup)
    start_controller()
    Dolphin.Fleet.set_source({Dolphin.Fleet.MAVLinkSource, nil})
    :ok
  end

  @doc "Makes the test node a distributed node on 127.0.0.1 (once; it stays so)."
  def start_controller do
    unless Node.alive?() do
      # EPMD and distribution on 127.0.0.1 only (Dolphin.Cluster starts an
      # EPMD if none runs; this one listens where the variable says).
      :ok = :application.set_env(:kernel, :inet_dist_use_interface, {127, 0, 0, 1})
      System.put_env("ERL_EPMD_ADDRESS", "127.0.0.1")
      {:ok, _} = Dolphin.Cluster.start_node(name("ctl") <> "@127.0.0.1", :longnames)
      System.delete_env("ERL_EPMD_ADDRESS")
    end

    Node.set_cookie(@cookie)

    on_exit(fn ->
      Dolphin.Test.GroundStation.forget_vehicles()
      for node <- Dolphin.Cluster.Mirror.joined(), do: Dolphin.Cluster.Mirror.unfollow(node)
    end)

    node()
  end

  @doc """
  Starts a peer node `NAME<N>@127.0.0.1` (`name/1`) with Dolphin running (at the test's
  speed-up) and returns `%{peer, node}`. Options: `:cookie` (default the
  test cluster's), `:speedup` (default the controller's).
  """
  def start_node(name, opts \\ []) do
    cookie = Keyword.get(opts, :cookie, @cookie)
    paths = Enum.flat_map(:code.get_path(), &[~c"-pa", &1])
    args = [~c"-setcookie", Atom.to_charlist(cookie), ~c"-kernel", ~c"inet_dist_use_interface", ~c"{127,0,0,1}", ~c"-kernel", ~c"logger_level", ~c"error"] ++ paths

    {:ok, peer, node} =
      :peer.start(%{name: String.to_atom(name(name)), host: ~c"127.0.0.1", longnames: true, args: args, connection: :standard_io, wait_boot: 60_000})

    on_exit(fn ->
      try do
        :peer.stop(peer)
      catch
        _, _ -> :ok
      end
    end)

    {:ok, _} = call(peer, Application, :ensure_all_started, [:elixir])
    {:ok, _} = call(peer, Application, :ensure_all_started, [:logger])
    :ok = call(peer, Logger, :configure, [[level: :error]])
    {:ok, _} = call(peer, Application, :ensure_all_started, [:dolphin])
    :ok = call(peer, Dolphin.Clock, :set_speedup, [Keyword.get(opts, :speedup, Dolphin.Clock.speedup())])
    %{peer: peer, node: node}
  end

  @doc """
  A station: a peer node with a link on 127.0.0.1 and, with `:sysids`,
  simulated vehicles of those system ids sending to it (`:sim` options
  are passed to `Dolphin.Sim.start/1`). Returns `%{peer, node, port}`.
  """
  def start_station(name, opts \\ []) do
    station = start_node(name, opts)
    {:ok, _} = call(station.peer, Dolphin.Link, :connect, ["udpin:127.0.0.1:0", [name: "gs"]])
    port = call(station.peer, Dolphin.Link.Connection, :port, ["gs"])

    if ids = opts[:sysids] do
      sim = Keyword.merge([gcs: port, sysids: ids, speedup: Dolphin.Clock.speedup()], Keyword.get(opts, :sim, []))
      {:ok, ^ids} = call(station.peer, Dolphin.Sim, :start, [sim])
    end

    Map.put(station, :port, port)
  end

  @doc "Calls `m.f(a)` on a peer."
  def call(peer, m, f, a, timeout \\ 30_000), do: :peer.call(peer, m, f, a, timeout)

  @doc "Waits until the controller sees `ids` connected, each with a position."
  def await_vehicles(ids, timeout \\ 20_000) do
    Dolphin.Test.Wait.until(
      fn -> Enum.all?(ids, fn id -> match?({:ok, %{connected?: true, position: %{}}}, Dolphin.Vehicles.view(id)) end) end,
      timeout,
      fn -> "vehicles #{inspect(ids)} on the controller; it sees #{inspect(Dolphin.Vehicles.list())}" end
    )
  end
end
