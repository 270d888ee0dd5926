# Several ground stations (Dolphin.Cluster) on this machine: a controller (this
# VM), two station nodes and one node of simulated vehicles, all on 127.0.0.1.
# The simulated vehicles (BENCH_VEHICLES, default 250: half send to each
# station) stand in for the radios of two sites; at speed-up BENCH_SPEEDUP
# (default 2) each sends its GLOBAL_POSITION_INT (asked for at 5 Hz of
# vehicle time) 10 times a second, plus its other telemetry.
#
# Printed, over BENCH_SECONDS (default 20) of steady state:
#   * the CPU of each node, as a share of one core (a station: its links,
#     vehicle processes and Dolphin.Cluster.Station; the simulator node apart);
#   * the telemetry latency from station to controller: from the moment a
#     view is published on the station to the moment the controller's mirror
#     publishes it locally (a probe subscribed on each node; the OS clock,
#     one on this machine, stamps both);
#   * the reaction of a condition on the controller to a change on a station:
#     `until(task, battery(v) < 0.3)` running on the controller for BENCH_REACTIONS
#     (default 40) remote vehicles; each vehicle's battery is dropped in turn,
#     and the time from the station's publication of the low view to the
#     task's stop callback on the controller is measured (target p99 < 20 ms).
#
# Why not 300 vehicles: a MAVLink system id is a byte (1..255), and one fleet
# cannot tell apart two vehicles of one id (two stations hearing one id with
# different vehicles are a conflict, Dolphin.Cluster.Choice.conflict/2). 250 is
# the most that fits in even halves.
#
#   MIX_ENV=prod mix run bench/cluster.exs

Code.require_file("percentiles.exs", __DIR__)

defmodule ClusterBench do
  alias Dolphin.Engine
  alias Dolphin.Engine.{Cond, Context, FakePlatform}

  # Compiled on every node: records when views arrive there.
  @probe """
  defmodule ClusterBench.Probe do
    def start(ids) do
      parent = self()

      pid =
        spawn(fn ->
          :ets.new(:bench_probe, [:named_table, :public, :set])
          Enum.each(ids, &Dolphin.Vehicles.subscribe/1)
          send(parent, :probe_ready)
          loop()
        end)

      receive do
        :probe_ready -> pid
      end
    end

    defp loop do
      receive do
        {:dolphin, {:vehicle, id}, {:view, v}} ->
          t = :os.system_time(:microsecond)
          :ets.insert_new(:bench_probe, {{id, :erlang.phash2(v)}, t})
          if is_number(v.battery) and v.battery < 0.3, do: :ets.insert_new(:bench_probe, {{:low, id}, t})
          loop()

        :clear ->
          :ets.delete_all_objects(:bench_probe)
          loop()
      end
    end

    def take, do: :ets.tab2list(:bench_probe)
    def clear(pid), do: send(pid, :clear)
  end
  """

  def main do
    n = env("BENCH_VEHICLES", 250)
    k = env("BENCH_SPEEDUP", 2)
    seconds = env("BENCH_SECONDS", 20)
    reactions = env("BENCH_REACTIONS", 40)
    if n > 254, do: Mix.raise("BENCH_VEHICLES: at most 254 (a MAVLink system id is 1..255)")
    half = div(n, 2)

    start_controller()
    Dolphin.Clock.set_speedup(k)
    IO.puts("cluster: #{n} simulated vehicles over 2 stations at speed-up #{k}; #{System.schedulers_online()} schedulers here, OTP #{System.otp_release()}, Elixir #{System.version()}")

    gs1 = station("bench_gs1", k)
    gs2 = station("bench_gs2", k)
    sims = node_up("bench_sims", k)
    ids1 = Enum.to_list(1..half)
    ids2 = Enum.to_list((half + 1)..n)
    {:ok, ^ids1} = call(sims, Dolphin.Sim, :start, [[gcs: gs1.port, first_sysid: 1, count: half, speedup: k]])
    {:ok, ^ids2} = call(sims, Dolphin.Sim, :start, [[gcs: gs2.port, first_sysid: half + 1, count: n - half, speedup: k]])

    :ok = Dolphin.Cluster.join(gs1.node, speedup: k)
    :ok = Dolphin.Cluster.join(gs2.node, speedup: k)
    t0 = System.monotonic_time(:millisecond)
    await(fn -> Enum.count(ids1 ++ ids2, &connected?/1) == n end, 180_000, "all #{n} vehicles on the controller")
    IO.puts("all #{n} vehicles known to the controller after #{System.monotonic_time(:millisecond) - t0} ms")

    # A vehicle on the ground publishes a view only when something changes:
    # they all take off and fly north, commanded from the controller through
    # their stations, so that every position report is a new view.
    t0 = System.monotonic_time(:millisecond)

    flying =
      (ids1 ++ ids2)
      |> Task.async_stream(&fly/1, max_concurrency: 64, timeout: 300_000)
      |> Enum.count(&match?({:ok, :ok}, &1))

    IO.puts("#{flying} of #{n} vehicles flying after #{System.monotonic_time(:millisecond) - t0} ms (take-off, then a go-to 5 km north); settling 3 s")
    Process.sleep(3_000)

    # Steady state: CPU and latency.
    probes = for {node, ids} <- [{gs1, ids1}, {gs2, ids2}], do: {node, call(node, ClusterBench.Probe, :start, [ids])}
    here = ClusterBench.Probe.start(ids1 ++ ids2)
    cpu0 = for p <- [gs1, gs2, sims], into: %{}, do: {p.name, call(p, :erlang, :statistics, [:runtime])}
    my0 = :erlang.statistics(:runtime)
    w0 = System.monotonic_time(:millisecond)
    Process.sleep(seconds * 1_000)
    wall = System.monotonic_time(:millisecond) - w0
    cpu1 = for p <- [gs1, gs2, sims], into: %{}, do: {p.name, call(p, :erlang, :statistics, [:runtime])}
    my1 = :erlang.statistics(:runtime)

    station_rows = Enum.flat_map(probes, fn {p, _} -> call(p, ClusterBench.Probe, :take, []) end) |> Map.new()
    latencies = for {key, t} <- ClusterBench.Probe.take(), match?({id, _} when is_integer(id), key), t0 = station_rows[key], do: t - t0
    views = length(latencies)

    IO.puts("\nCPU over #{Float.round(wall / 1000, 1)} s (share of one core; 2 vCPUs shared by all nodes):")
    for p <- [gs1, gs2, sims], do: IO.puts("  #{String.pad_trailing(p.name, 10)} #{pct(cpu1[p.name], cpu0[p.name], wall)}")
    IO.puts("  #{String.pad_trailing("controller", 10)} #{pct(my1, my0, wall)}")
    IO.puts("\nviews mirrored: #{views} (#{round(views / (wall / 1000))}/s)")
    row("telemetry latency station -> controller", stats(latencies))

    # Reaction: conditions on the controller, changes on the stations.
    Enum.each(probes, fn {p, pid} -> call(p, ClusterBench.Probe, :clear, [pid]) end)
    ClusterBench.Probe.clear(here)
    sample = Enum.take_random(ids1 ++ ids2, reactions)
    Context.put(%Context{fleet: Dolphin.Fleet, source: {Dolphin.Fleet.MAVLinkSource, nil}, owner: self()})
    {:ok, _} = Dolphin.Fleet.pick(Dolphin.Fleet, self(), id: sample, count: length(sample), timeout: 30_000)

    tasks =
      for v <- sample do
        task = FakePlatform.task("t#{v}", duration: :infinity, notify: self())
        Engine.on(Engine.until(task, Cond.new(fn -> (Dolphin.Engine.Watcher.vehicle(v).battery || 1.0) < 0.3 end, source: "battery(v) < 0.3")), [v])
      end

    {:ok, run} = Engine.start(Engine.concurrent(tasks))
    for _ <- sample, do: receive(do: ({:fake_platform, :started, _} -> :ok))
    Process.sleep(500)

    stopped =
      for v <- sample do
        name = "t#{v}"
        :ok = call(sims, Dolphin.Sim, :set_battery, [v, 0.2])

        receive do
          {:fake_platform, :stopped, %{name: ^name}} -> {v, :os.system_time(:microsecond)}
        after
          30_000 -> Mix.raise("the condition on vehicle #{v} never held")
        end
      end

    lows = Enum.flat_map(probes, fn {p, _} -> call(p, ClusterBench.Probe, :take, []) end) |> Map.new()
    reaction = for {v, t} <- stopped, t0 = lows[{:low, v}], do: t - t0
    row("condition reaction (station view -> stop)", stats(reaction))
    _ = Engine.stop(run)
    IO.puts("\n(p99 target of the reaction: < 20 ms = 20000 µs)")
  end

  defp fly(id) do
    alias Dolphin.Vehicles.Manoeuvres
    {:ok, %{position: p}} = Dolphin.Vehicles.view(id)

    with :ok <- Manoeuvres.take_off(id, 30, within: 120_000) do
      await(fn -> match?({:ok, %{relative_altitude: h}} when is_number(h) and h > 20, Dolphin.Vehicles.view(id)) end, 120_000, "vehicle #{id} up")
      Manoeuvres.go_to(id, {p.lat + 0.05, p.lon, 30})
    end
  end

  defp connected?(id), do: match?({:ok, %{connected?: true, position: %{}}}, Dolphin.Vehicles.view(id))

  defp pct({total1, _}, {total0, _}, wall), do: "#{Float.round((total1 - total0) / wall * 100, 1)} %"

  defp env(name, default), do: String.to_integer(System.get_env(name, Integer.to_string(default)))

  defp start_controller do
    unless Node.alive?() do
      {:ok, _} = Dolphin.Cluster.start_node("bench_ctl@127.0.0.1", :longnames, "dolphin_bench")
    end

    Node.set_cookie(:dolphin_bench)
    Code.compile_string(@probe)
  end

  defp node_up(name, k) do
    paths = Enum.flat_map(:code.get_path(), &[~c"-pa", &1])
    args = [~c"-setcookie", ~c"dolphin_bench", ~c"-kernel", ~c"logger_level", ~c"error"] ++ paths
    {:ok, peer, node} = :peer.start(%{name: String.to_atom(name), host: ~c"127.0.0.1", longnames: true, args: args, connection: :standard_io, wait_boot: 60_000})
    p = %{peer: peer, node: node, name: name}
    {:ok, _} = call(p, Application, :ensure_all_started, [:elixir])
    {:ok, _} = call(p, Application, :ensure_all_started, [:logger])
    :ok = call(p, Logger, :configure, [[level: :error]])
    {:ok, _} = call(p, Application, :ensure_all_started, [:dolphin])
    :ok = call(p, Dolphin.Clock, :set_speedup, [k])
    _ = call(p, Code, :compile_string, [@probe])
    p
  end

  defp station(name, k) do
    p = node_up(name, k)
    {:ok, _} = call(p, Dolphin.Link, :connect, ["udpin:127.0.0.1:0", [name: "bench"]])
    Map.put(p, :port, call(p, Dolphin.Link.Connection, :port, ["bench"]))
  end

  defp call(%{peer: peer}, m, f, a), do: :peer.call(peer, m, f, a, 60_000)

  defp await(fun, timeout, what) do
    deadline = System.monotonic_time(:millisecond) + timeout

    Stream.repeatedly(fn -> fun.() || (Process.sleep(200) && false) end)
    |> Enum.find(fn ok -> ok or System.monotonic_time(:millisecond) > deadline end) ||
      Mix.raise("timed out waiting for #{what}")
  end

  defp stats(samples), do: Bench.Percentiles.of(samples)

  defp row(label, %{n: n, p50: p50, p99: p99, max: max}),
    do: IO.puts(String.pad_trailing(label, 44) <> "n=#{n}  p50 #{p50} µs  p99 #{p99} µs  max #{max} µs")
end

ClusterBench.main()
