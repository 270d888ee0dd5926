# The ground station's telemetry intake at fleet scale.
#
#   VEHICLES simulated vehicles (default 2,000) over NETWORKS networks
#   (default 8, system ids repeating on each) run in *another OS process*
#   (`mix dolphin.sim --count VEHICLES --networks NETWORKS`), each sending
#   from its own UDP socket what the ground station asks every vehicle for
#   (its usual telemetry: GLOBAL_POSITION_INT at 5 Hz, SYS_STATUS, ATTITUDE,
#   VFR_HUD, MISSION_CURRENT, ... at 1-2 Hz, HEARTBEAT at 1 Hz: ~16 frames
#   a second). This VM is the ground station: one `udpin` link per network,
#   a vehicle process per vehicle, the views every reader reads.
#
#   Once every vehicle is discovered and its telemetry flows, the bench
#   measures over WINDOW seconds (default 10): frames received a second,
#   the CPU of this VM (all its threads: /proc/self/stat) per frame and per
#   vehicle, and the simulator's CPU beside it. Frames lost to the ground
#   station's own slowness are the datagrams the kernel dropped for want of
#   room in the links' sockets (/proc/net/udp, per socket: each link asks
#   for a 4 MiB buffer), in the window and over the whole run (discovery
#   included); /proc/net/snmp's RcvbufErrors adds what the simulator's own
#   sockets dropped. (A frame taken from a socket is never dropped after:
#   mailboxes are unbounded.)
#
#   MIX_ENV=prod mix run bench/intake.exs     (VEHICLES=500 NETWORKS=2 WINDOW=5 for a smaller one)
#
#   FEED=replay: the vehicles replayed instead of simulated
#   (bench/replay_feed.exs: telemetry encoded beforehand, sent by one
#   Python process, each vehicle from its own socket, RATE frames a second
#   a vehicle, default 11: positions at 9 Hz, SYS_STATUS and HEARTBEAT at
#   1 Hz, each position a new one). The simulator of 2,000 vehicles needs
#   more than this machine's two cores beside the ground station; the feed
#   took a fifth of one at 2,000. Nothing answers the ground station's
#   requests there (the unique id comes in the cycle), and every vehicle
#   moves, so each position is a view published.
#
#   ON_CPU=1 adds how long the ground station's processes ran over the window
#   (traced: scheduled in to scheduled out), by kind, against its whole CPU.
#
#   The ground station's VM as docs/operating.md advises for a large fleet
#   (no busy-waiting schedulers; the simulator's VM keeps the defaults):
#   MIX_ENV=prod elixir --erl "+sbwt none +sbwtdcpu none +sbwtdio none" -S mix run bench/intake.exs

Code.require_file("os_process.exs", __DIR__)
Code.require_file("replay_feed.exs", __DIR__)

alias Dolphin.Link
alias Dolphin.Link.Connection

vehicles = String.to_integer(System.get_env("VEHICLES", "2000"))
networks = String.to_integer(System.get_env("NETWORKS", "8"))
window_s = String.to_integer(System.get_env("WINDOW", "10"))
feed = System.get_env("FEED", "sim")
rate = String.to_integer(System.get_env("RATE", "11"))
per_network = div(vehicles + networks - 1, networks)

cond do
  feed not in ["sim", "replay"] -> Mix.raise("FEED: sim or replay, not #{inspect(feed)}")
  per_network > 255 -> Mix.raise("#{vehicles} vehicles over #{networks} networks: at most 255 a network (a system id is a byte)")
  true -> :ok
end

defmodule Bench.Intake do
  def rcvbuf_errors do
    [names, values | _] = File.read!("/proc/net/snmp") |> String.split("\n") |> Enum.filter(&String.starts_with?(&1, "Udp:"))
    Enum.zip(String.split(names), String.split(values)) |> Map.new() |> Map.fetch!("RcvbufErrors") |> String.to_integer()
  end

  # Datagrams the kernel dropped on the UDP sockets bound to `ports` (the
  # last column of /proc/net/udp, per socket).
  def socket_drops(ports) do
    wanted = MapSet.new(ports)

    "/proc/net/udp"
    |> File.read!()
    |> String.split("\n", trim: true)
    |> Enum.drop(1)
    |> Enum.map(&String.split/1)
    |> Enum.filter(fn [_sl, local | _] -> MapSet.member?(wanted, local |> String.split(":") |> List.last() |> String.to_integer(16)) end)
    |> Enum.map(&(&1 |> List.last() |> String.to_integer()))
    |> Enum.sum()
  end

  # One udpin link per network, on consecutive ports of 127.0.0.1.
  def open_links(networks) do
    base = 20_000 + :rand.uniform(40_000)

    results = for k <- 1..networks, do: Link.connect("udpin:127.0.0.1:#{base + k - 1}", name: "net#{k}")

    if Enum.all?(results, &match?({:ok, _}, &1)) do
      {base, for(k <- 1..networks, do: "net#{k}")}
    else
      for {:ok, link} <- results, do: Link.disconnect(link)
      open_links(networks)
    end
  end

  # A tracer of every process's scheduling, summing the µs each kind of
  # process ran (its initial call: the link, a vehicle, ...).
  def start_on_cpu do
    tracer = spawn(fn -> on_cpu_loop(%{}, %{}) end)
    :erlang.trace(:all, true, [:running, :monotonic_timestamp, {:tracer, tracer}])
    tracer
  end

  def stop_on_cpu(tracer) do
    :erlang.trace(:all, false, [:running])
    send(tracer, {:done, self()})

    receive do
      {:on_cpu, totals} -> totals
    end
  end

  defp on_cpu_loop(since, totals) do
    receive do
      {:trace_ts, pid, :in, _mfa, t} ->
        on_cpu_loop(Map.put(since, pid, t), totals)

      {:trace_ts, pid, :out, _mfa, t} ->
        case Map.pop(since, pid) do
          {nil, since} -> on_cpu_loop(since, totals)
          {t0, since} -> on_cpu_loop(since, Map.update(totals, pid, t - t0, &(&1 + t - t0)))
        end

      {:done, from} ->
        # Drained: the trace messages still queued came before the :done.
        by_kind =
          Enum.reduce(totals, %{}, fn {pid, native}, acc ->
            Map.update(acc, kind(pid), native, &(&1 + native))
          end)

        send(from, {:on_cpu, Map.new(by_kind, fn {k, native} -> {k, System.convert_time_unit(native, :native, :microsecond)} end)})
    end
  end

  # A process's kind: proc_lib's initial call, else its registered name, else its initial call.
  def kind(pid) do
    case Process.info(pid, [:dictionary, :registered_name, :initial_call]) do
      nil -> :gone
      info -> info[:dictionary][:"$initial_call"] || (info[:registered_name] != [] && info[:registered_name]) || info[:initial_call]
    end
  end

  def frames(links), do: links |> Enum.map(&Connection.info(&1).stats.frames) |> Enum.sum()

  def wait_until(what, timeout_ms, fun) do
    deadline = System.monotonic_time(:millisecond) + timeout_ms

    Stream.repeatedly(fn -> Process.sleep(500) && fun.() end)
    |> Enum.find(fn ok -> ok or System.monotonic_time(:millisecond) > deadline end) ||
      raise "#{what}: not within #{div(timeout_ms, 1000)} s"
  end
end

alias Bench.Intake

{base, links} = Intake.open_links(networks)
rcvbuf0 = Intake.rcvbuf_errors()

# Discovery and the telemetry requests take a while for thousands of
# vehicles: the simulator runs long enough for that and the window.
discovery_s = 30 + div(vehicles * 60, 1000)
run_s = discovery_s + 60 + window_s
{sim, sim_pid} =
  case feed do
    "sim" ->
      mix = System.find_executable("mix")
      args = ~w(dolphin.sim --count #{vehicles} --networks #{networks} --gcs udpout:127.0.0.1:#{base} --for #{run_s})
      sim = Port.open({:spawn_executable, mix}, [:binary, :exit_status, {:line, 4096}, args: args, env: [{~c"MIX_ENV", ~c"#{Mix.env()}"}]])
      {:os_pid, sim_pid} = Port.info(sim, :os_pid)
      Bench.OSProcess.await_line(sim, ~r/^simulating/, 120_000)
      {sim, sim_pid}

    "replay" ->
      # Vehicle k of network n: system id k + 1, unique id n * per_network + k + 1.
      replayed = for i <- 0..(vehicles - 1), do: %{port: base + div(i, per_network), sysid: rem(i, per_network) + 1, index: i}
      replay = Bench.ReplayFeed.start(replayed, rate)
      {replay, replay.os_pid}
  end

source = if feed == "sim", do: "simulated vehicles", else: "vehicles replayed at #{rate} frames a second each (bench/replay_feed.py)"

# The emulator's own flags (before "--" on its command line): the schedulers' busy waiting among them.
vm_flags = File.read!("/proc/self/cmdline") |> String.split(<<0>>) |> Enum.drop(1) |> Enum.take_while(&(&1 != "--")) |> Enum.join(" ")
IO.puts("telemetry intake: #{vehicles} #{source} over #{networks} networks (another OS process), #{System.schedulers_online()} schedulers, OTP #{System.otp_release()}, VM flags: #{if vm_flags == "", do: "none", else: vm_flags}")

started = System.monotonic_time(:millisecond)

try do
  Intake.wait_until("every vehicle discovered", discovery_s * 1000, fn ->
    n = length(Dolphin.Vehicles.list())
    if System.get_env("DEBUG"), do: IO.puts("  #{n} discovered")
    n >= vehicles
  end)
rescue
  e ->
    # Which system ids were heard fewer times than there are networks.
    short = Dolphin.Vehicles.list() |> Enum.frequencies_by(&Dolphin.Vehicles.Id.sysid/1) |> Enum.filter(fn {_, n} -> n < networks end)
    IO.puts("  system ids heard on fewer than #{networks} networks: #{inspect(short)}")
    for {sysid, _} <- Enum.take(short, 2), do: IO.inspect(:sys.get_state(Dolphin.Vehicles.whereis(sysid)).paths, label: "  paths of #{sysid}")
    reraise e, __STACKTRACE__
end

discovered_s = (System.monotonic_time(:millisecond) - started) / 1000

# Telemetry flowing: the rate of frames steady (two 2-second rates within 5 %).
rate = fn ->
  f0 = Intake.frames(links)
  Process.sleep(2_000)
  (Intake.frames(links) - f0) / 2
end

Intake.wait_until("the telemetry steady", 60_000, fn ->
  {a, b} = {rate.(), rate.()}
  a > 0 and abs(a - b) / a < 0.05
end)

reductions = fn -> for pid <- Process.list(), {:reductions, r} <- [Process.info(pid, :reductions)], into: %{}, do: {pid, r} end
red0 = if System.get_env("DEBUG"), do: reductions.()
ports = Enum.to_list(base..(base + networks - 1))
drops0 = Intake.socket_drops(ports)
frames0 = Intake.frames(links)
cpu0 = Bench.OSProcess.cpu_ms(System.pid())
sim_cpu0 = Bench.OSProcess.cpu_ms(sim_pid)
wall0 = System.monotonic_time(:millisecond)
# ON_CPU=1: how long the processes ran (scheduled in to scheduled out), by
# kind, over the window: the rest of the VM's CPU is the runtime's outside
# any process (schedulers, polling, ports) and the kernel's.
on_cpu = if System.get_env("ON_CPU"), do: Intake.start_on_cpu()

# PERF=FILE: a perf profile of this VM over the window (run with ERL_FLAGS="+JPperf true").
if perf = System.get_env("PERF"),
  do: System.cmd("perf", ["record", "-F", "999", "-g", "-p", System.pid(), "-o", perf, "--", "sleep", "#{window_s}"], stderr_to_stdout: true),
  else: Process.sleep(window_s * 1000)

on_cpu = on_cpu && Intake.stop_on_cpu(on_cpu)

frames1 = Intake.frames(links)
cpu1 = Bench.OSProcess.cpu_ms(System.pid())
sim_cpu1 = Bench.OSProcess.cpu_ms(sim_pid)
wall1 = System.monotonic_time(:millisecond)
window_drops = Intake.socket_drops(ports) - drops0

frames = frames1 - frames0

if red0 do
  # Where the work went: reductions by kind of process.
  reductions.()
  |> Enum.map(fn {pid, r} -> {Intake.kind(pid), r - Map.get(red0, pid, 0)} end)
  |> Enum.group_by(&elem(&1, 0), &elem(&1, 1))
  |> Enum.map(fn {k, rs} -> {k, Enum.sum(rs), length(rs)} end)
  |> Enum.sort_by(&(-elem(&1, 1)))
  |> Enum.take(12)
  |> Enum.each(fn {k, r, n} -> IO.puts("  #{inspect(k)}: #{r} reductions in #{n} process(es)") end)
end

wall_ms = wall1 - wall0
cpu_ms = cpu1 - cpu0

# The simulator's end (the feed's at once): how many frames its vehicles sent.
sent =
  case feed do
    "sim" ->
      [_, sent] = Regex.run(~r/sent (\d+) frames/, Bench.OSProcess.await_line(sim, ~r/sent \d+ frames/, (run_s + 120) * 1000))
      receive do: ({^sim, {:exit_status, _}} -> :ok), after: (30_000 -> :ok)
      String.to_integer(sent)

    "replay" ->
      Bench.ReplayFeed.stop(sim)
  end

# What was still in a socket or a mailbox when the simulator stopped.
Process.sleep(1_000)
received = Intake.frames(links)
kernel_drops = Intake.rcvbuf_errors() - rcvbuf0
ours = Intake.socket_drops(ports)

IO.puts("""
  all #{vehicles} discovered in #{Float.round(discovered_s, 1)} s; measured over #{wall_ms} ms once their telemetry was steady:
  #{frames} frames received (#{round(frames * 1000 / wall_ms)} frames/s, #{Float.round(frames * 1000 / wall_ms / vehicles, 1)} a vehicle)
  ground station CPU #{cpu_ms} ms = #{Float.round(cpu_ms / wall_ms * 100, 1)} % of one core, #{Float.round(cpu_ms / wall_ms * 100 / vehicles, 4)} % a vehicle, \
#{Float.round(cpu_ms * 1000 / max(frames, 1), 2)} µs of CPU a frame
  #{if feed == "sim", do: "simulator", else: "feed"} CPU #{Float.round((sim_cpu1 - sim_cpu0) / wall_ms * 100, 1)} % of one core
  lost to the ground station's slowness (datagrams the kernel dropped for want of room in its sockets): #{window_drops} in the window
  over the whole run, discovery included: #{ours} of #{received} received (#{kernel_drops} machine-wide, the #{if feed == "sim", do: "simulator", else: "feed"}'s sockets \
included); #{if feed == "sim", do: "the simulator counted #{sent} frames sent by the vehicles that answered at its end", else: "the feed sent #{sent}"}
""")

if on_cpu do
  # The tracer's own time is not counted; tracing itself costs the traced some.
  in_processes = on_cpu |> Map.values() |> Enum.sum()
  per_frame = fn us -> Float.round(us / max(frames, 1), 2) end
  IO.puts("  (ON_CPU) the processes ran #{per_frame.(in_processes)} µs a frame of the #{Float.round(cpu_ms * 1000 / max(frames, 1), 2)} (tracing included); by kind:")

  on_cpu
  |> Enum.sort_by(&(-elem(&1, 1)))
  |> Enum.take(8)
  |> Enum.each(fn {kind, us} -> IO.puts("    #{inspect(kind)}: #{per_frame.(us)} µs a frame") end)
end
