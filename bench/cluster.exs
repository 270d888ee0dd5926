# Several ground stations (Dolphin.Cluster) on this machine: a controller (this
# VM) and BENCH_STATIONS station nodes (default 2), all on 127.0.0.1, with
# BENCH_VEHICLES vehicles (default 250) shared out evenly. Every station's
# vehicles are system ids 1, 2, ..., as two sites that numbered their fleets
# alike: on the controller one station's keep their ids and the others' are
# named apart, "ID@NODE" (Dolphin.Cluster.Mirror), so that the controller
# holds more than 255. The vehicles come from one of two feeds (BENCH_FEED):
#
#   sim (default): for each station, a node of simulated vehicles
#     (Dolphin.Sim), at most 254 a station, at speed-up BENCH_SPEEDUP
#     (default 2). Each sends its GLOBAL_POSITION_INT (asked for at 5 Hz of
#     vehicle time) 10 times a second, plus its other telemetry; they take
#     off and fly north, commanded from the controller, so that every
#     position report is a new view. The simulators cost more CPU than the
#     stations: this machine runs a few hundred vehicles this way.
#   replay: telemetry encoded beforehand, sent by one OS process
#     (bench/replay_feed.exs), each vehicle from its own UDP socket:
#     BENCH_RATE (default 2) GLOBAL_POSITION_INT a second, each a new
#     position, plus a SYS_STATUS and a HEARTBEAT a second and its
#     AUTOPILOT_VERSION (a unique id) once a cycle of 256 frames. A station
#     of more than 250 vehicles gets a `udpin` link per 250, each its own
#     network ("7@net2" on the station). Sending is all the feed costs, so
#     thousands of vehicles fit on this machine; speed-up BENCH_SPEEDUP
#     (default 1: the frames come in real time).
#
# Printed, over BENCH_SECONDS (default 20) of steady state:
#   * the CPU of each node, as a share of one core (a station: its links,
#     vehicle processes and Dolphin.Cluster.Station; the feed apart);
#   * the telemetry latency from station to controller: from the moment a
#     view is published on the station to the moment the controller's mirror
#     publishes it locally (a probe subscribed on each node; the OS clock,
#     one on this machine, stamps both; a view is matched by its content,
#     its id aside);
#   * the reaction of a condition on the controller to a change on a station:
#     `until(task, battery(v) < 0.3)` running on the controller for BENCH_REACTIONS
#     (default 40) remote vehicles; each vehicle's battery is dropped in turn,
#     and the time from the station's publication of the low view to the
#     task's stop callback on the controller is measured (target p99 < 20 ms).
#
# Until a station's vehicle i is known to be another autopilot than the
# first station's i (its unique id comes a moment after its first
# HEARTBEAT), the controller takes the two for one vehicle heard twice; the
# bench waits until it holds all of them apart, and reads from the mirror's
# routes which station each of its ids is.
#
#   MIX_ENV=prod mix run bench/cluster.exs
#   BENCH_FEED=replay BENCH_VEHICLES=2000 BENCH_STATIONS=4 MIX_ENV=prod mix run bench/cluster.exs

Code.require_file("percentiles.exs", __DIR__)
Code.require_file("os_process.exs", __DIR__)
Code.require_file("replay_feed.exs", __DIR__)

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
          # (By content: the controller names some vehicles apart, and its views carry no network.)
          :ets.insert_new(:bench_probe, {{id, :erlang.phash2(%{v | id: nil, network: nil})}, t})
          if is_number(v.battery) and v.battery < 0.3, do: :ets.insert_new(:bench_probe, {{:low, id}, t})
          loop()

        :clear ->
          :ets.delete_all_objects(:bench_probe)
          loop()

        :lows_only ->
          :ets.delete_all_objects(:bench_probe)
          lows_loop()
      end
    end

    # The reaction's part: only when each vehicle's low view came.
    defp lows_loop do
      receive do
        {:dolphin, {:vehicle, id}, {:view, v}} ->
          if is_number(v.battery) and v.battery < 0.3, do: :ets.insert_new(:bench_probe, {{:low, id}, :os.system_time(:microsecond)})
          lows_loop()
      end
    end

    def take, do: :ets.tab2list(:bench_probe)
    def clear(pid), do: send(pid, :clear)
    def lows_only(pid), do: send(pid, :lows_only)
  end
  """

  def main do
    n = env("BENCH_VEHICLES", 250)
    m = env("BENCH_STATIONS", 2)
    feed = System.get_env("BENCH_FEED", "sim")
    k = env("BENCH_SPEEDUP", if(feed == "replay", do: 1, else: 2))
    rate = env("BENCH_RATE", 2)
    seconds = env("BENCH_SECONDS", 20)
    reactions = env("BENCH_REACTIONS", 40)
    per = div(n, m)

    cond do
      feed not in ["sim", "replay"] -> Mix.raise("BENCH_FEED: sim or replay, not #{inspect(feed)}")
      per * m != n -> Mix.raise("BENCH_VEHICLES: a multiple of BENCH_STATIONS")
      feed == "sim" and per > 254 -> Mix.raise("BENCH_VEHICLES: at most 254 a station with BENCH_FEED=sim (a MAVLink system id is 1..255); BENCH_FEED=replay for more")
      true -> :ok
    end

    start_controller()
    Dolphin.Clock.set_speedup(k)

    what = if feed == "sim", do: "simulated vehicles", else: "vehicles replayed (#{rate} positions a second each)"
    IO.puts("cluster: #{n} #{what} over #{m} stations (#{per} a station, system ids from 1 on each) at speed-up #{k}; #{System.schedulers_online()} schedulers here, OTP #{System.otp_release()}, Elixir #{System.version()}")

    {stations, feeder} = if feed == "sim", do: {sim_stations(m, per, k), nil}, else: replay_stations(m, per, k, rate)

    for st <- stations, do: :ok = Dolphin.Cluster.join(st.gs.node, speedup: k)
    t0 = System.monotonic_time(:millisecond)
    await(fn -> Enum.count(Dolphin.Vehicles.list(), &connected?/1) == n end, 300_000, "all #{n} vehicles on the controller, held apart")
    IO.puts("all #{n} vehicles known to the controller after #{System.monotonic_time(:millisecond) - t0} ms")

    # Each id here: its station and its id there.
    by_node = Map.new(stations, &{&1.gs.node, &1})
    where = Map.new(Dolphin.Cluster.Mirror.routes(), fn {id, %{chosen: node}} -> {id, {by_node[node], local_id(id, node)}} end)
    ids = Dolphin.Vehicles.Id.sort(Map.keys(where))
    stations = Enum.map(stations, &Map.put(&1, :ids, call(&1.gs, Dolphin.Vehicles, :list, [])))

    if feed == "sim" do
      # A vehicle on the ground publishes a view only when something changes:
      # they all take off and fly north, commanded from the controller through
      # their stations, so that every position report is a new view.
      t0 = System.monotonic_time(:millisecond)

      flying =
        ids
        |> Task.async_stream(&fly/1, max_concurrency: 64, timeout: 300_000)
        |> Enum.count(&match?({:ok, :ok}, &1))

      IO.puts("#{flying} of #{n} vehicles flying after #{System.monotonic_time(:millisecond) - t0} ms (take-off, then a go-to 5 km north)")
    end

    IO.puts("settling 3 s")
    Process.sleep(3_000)

    # Steady state: CPU and latency.
    probes = for st <- stations, into: %{}, do: {st.gs.node, call(st.gs, ClusterBench.Probe, :start, [st.ids])}
    here = ClusterBench.Probe.start(ids)
    nodes = Enum.flat_map(stations, &Enum.reject([&1.gs, &1.sims], fn p -> p == nil end))
    cpu0 = for p <- nodes, into: %{}, do: {p.name, call(p, :erlang, :statistics, [:runtime])}
    feeder_cpu0 = feeder && Bench.OSProcess.cpu_ms(feeder.os_pid)
    my0 = :erlang.statistics(:runtime)
    w0 = System.monotonic_time(:millisecond)
    Process.sleep(seconds * 1_000)
    wall = System.monotonic_time(:millisecond) - w0
    cpu1 = for p <- nodes, into: %{}, do: {p.name, call(p, :erlang, :statistics, [:runtime])}
    feeder_cpu1 = feeder && Bench.OSProcess.cpu_ms(feeder.os_pid)
    my1 = :erlang.statistics(:runtime)

    published = for st <- stations, into: %{}, do: {st.gs.node, Map.new(call(st.gs, ClusterBench.Probe, :take, []))}

    latencies =
      for {{id, hash}, t} <- ClusterBench.Probe.take(), Map.has_key?(where, id), {st, local} = where[id], t0 = published[st.gs.node][{local, hash}], do: t - t0

    views = length(latencies)

    IO.puts("\nCPU over #{Float.round(wall / 1000, 1)} s (share of one core; #{System.schedulers_online()} vCPUs shared by all nodes):")
    for p <- nodes, do: IO.puts("  #{String.pad_trailing(p.name, 12)} #{pct(cpu1[p.name], cpu0[p.name], wall)}")
    if feeder, do: IO.puts("  #{String.pad_trailing("feed", 12)} #{Float.round((feeder_cpu1 - feeder_cpu0) / wall * 100, 1)} % (bench/replay_feed.py)")
    controller_ms = elem(my1, 0) - elem(my0, 0)
    per_view = if views > 0, do: Float.round(controller_ms * 1000 / views, 1), else: "-"
    IO.puts("  #{String.pad_trailing("controller", 12)} #{pct(my1, my0, wall)}: #{round(controller_ms / wall * 1_000_000 / n)} µs of CPU a second per vehicle, #{per_view} µs per view mirrored")
    IO.puts("\nviews mirrored: #{views} (#{round(views / (wall / 1000))}/s)")
    row("telemetry latency station -> controller", stats(latencies))

    # Reaction: conditions on the controller, changes on the stations.
    Enum.each(stations, fn st -> call(st.gs, ClusterBench.Probe, :lows_only, [probes[st.gs.node]]) end)
    ClusterBench.Probe.lows_only(here)
    sample = Enum.take_random(ids, reactions)
    Context.put(%Context{fleet: Dolphin.Fleet, source: {Dolphin.Fleet.MAVLinkSource, nil}, owner: self()})
    Dolphin.Vehicles.subscribe(:all)
    {:ok, _} = Dolphin.Fleet.pick(Dolphin.Fleet, self(), id: sample, count: length(sample), timeout: 30_000)

    tasks =
      for v <- sample do
        task = FakePlatform.task("t#{v}", duration: :infinity, notify: self())
        Engine.on(Engine.until(task, Cond.new(fn -> (Dolphin.Engine.Watcher.vehicle(v).battery || 1.0) < 0.3 end, source: "battery(v) < 0.3")), [v])
      end

    {:ok, run} = Engine.start(Engine.concurrent(tasks))

    for _ <- sample do
      receive do
        {:fake_platform, :started, _} -> :ok
        {Dolphin.Engine, _run, {:error, e}} -> Mix.raise("the reaction's run failed: #{Exception.message(e)}\n#{lost_report(sample)}")
      end
    end

    Process.sleep(500)

    stopped =
      for v <- sample do
        name = "t#{v}"
        {st, local} = where[v]
        drop_battery(st, local, v, feeder)

        receive do
          {:fake_platform, :stopped, %{name: ^name}} -> {v, :os.system_time(:microsecond)}
        after
          30_000 -> Mix.raise("the condition on vehicle #{v} never held")
        end
      end

    lows = for st <- stations, into: %{}, do: {st.gs.node, Map.new(call(st.gs, ClusterBench.Probe, :take, []))}
    reaction = for {v, t} <- stopped, {st, local} = where[v], t0 = lows[st.gs.node][{:low, local}], do: t - t0
    row("condition reaction (station view -> stop)", stats(reaction))
    _ = Engine.stop(run)
    IO.puts("\n(p99 target of the reaction: < 20 ms = 20000 µs)")
    if feeder, do: Port.close(feeder.port)
  end

  # Which vehicles of `ids` the controller does not have connected now, and since when (events kept by Dolphin.Events).
  defp lost_report(ids) do
    now = for id <- ids, {:ok, %{connected?: false} = v} <- [Dolphin.Vehicles.view(id)], into: "" do
      "  #{inspect(id)} not connected here: heard by #{inspect(Dolphin.Cluster.Mirror.heard_as(id))}, view #{inspect(Map.take(v, [:boot_ms, :uid, :network]))}\n"
    end

    # What the controller said of them meanwhile (the bench follows :vehicles from the pick on).
    told = Stream.repeatedly(fn -> receive(do: ({:dolphin, :vehicles, e} -> e), after: (0 -> nil)) end) |> Enum.take_while(& &1) |> Enum.filter(fn {_, id} -> id in ids end)
    now <> "  events: #{inspect(told)}"
  end

  defp drop_battery(%{sims: sims}, local, _v, nil), do: :ok = call(sims, Dolphin.Sim, :set_battery, [local, 0.2])

  # The feed's vehicles are numbered by their unique ids (index + 1).
  defp drop_battery(_st, _local, v, feeder) do
    {:ok, %{uid: uid}} = Dolphin.Vehicles.view(v)
    Bench.ReplayFeed.low_battery(feeder, uid - 1)
    :ok
  end

  defp sim_stations(m, per, k) do
    for i <- 1..m do
      gs = station("bench_gs#{i}", k)
      sims = node_up("bench_sims#{i}", k)
      ids = Enum.to_list(1..per)
      {:ok, ^ids} = call(sims, Dolphin.Sim, :start, [[gcs: gs.port, first_sysid: 1, count: per, speedup: k]])
      %{gs: gs, sims: sims}
    end
  end

  # Stations with a `udpin` link per 250 vehicles, each link its own network,
  # and the feed that sends to them.
  @per_network 250
  defp replay_stations(m, per, k, rate) do
    networks = div(per + @per_network - 1, @per_network)

    stations =
      for i <- 1..m do
        p = node_up("bench_gs#{i}", k)

        ports =
          for j <- 1..networks do
            {:ok, _} = call(p, Dolphin.Link, :connect, ["udpin:127.0.0.1:0", [name: "net#{j}", network: "net#{j}"]])
            call(p, Dolphin.Link.Connection, :port, ["net#{j}"])
          end

        %{gs: p, sims: nil, ports: ports}
      end

    # Vehicle `index` (0-based over all stations) has unique id index + 1.
    vehicles =
      for {st, i} <- Enum.with_index(stations), j <- 0..(per - 1) do
        %{port: Enum.at(st.ports, div(j, @per_network)), sysid: rem(j, @per_network) + 1, index: i * per + j}
      end

    # A position `rate` times a second, a SYS_STATUS and a HEARTBEAT.
    {stations, Bench.ReplayFeed.start(vehicles, rate + 2)}
  end

  # Its id on its station ("7@bench_gs2" is 7 there, "7@net2@bench_gs2" is "7@net2").
  defp local_id(id, node) do
    {^node, there} = List.keyfind(Dolphin.Cluster.Mirror.heard_as(id), node, 0)
    there
  end

  defp fly(id) do
    alias Dolphin.Vehicles.Manoeuvres
    {:ok, %{position: p}} = Dolphin.Vehicles.view(id)

    with :ok <- Manoeuvres.take_off(id, 30, within: 120_000) do
      await(fn -> match?({:ok, %{relative_altitude: h}} when is_number(h) and h > 20, Dolphin.Vehicles.view(id)) end, 120_000, "vehicle #{id} up")
      Manoeuvres.go_to(id, {p.lat + 0.05, p.lon, 30})
    end
  end

  # Heard, placed, and known by its autopilot's unique id (held apart from its namesakes for good).
  defp connected?(id), do: match?({:ok, %{connected?: true, position: %{}, uid: uid}} when is_integer(uid), Dolphin.Vehicles.view(id))

  defp pct({total1, _}, {total0, _}, wall), do: "#{Float.round((total1 - total0) / wall * 100, 1)} %"

  defp env(name, default), do: String.to_integer(System.get_env(name, Integer.to_string(default)))

  defp start_controller do
    unless Node.alive?() do
      {:ok, _} = Dolphin.Cluster.start_node("bench_ctl@127.0.0.1", :longnames, "dolphin_bench")
    end

    Node.set_cookie(:dolphin_bench)
    # (Each vehicle a second station names apart is a warning here: thousands.)
    Logger.configure(level: :error)
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
