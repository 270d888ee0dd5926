# The simulator's capacity.
#
#   1. How many simulated vehicles one machine sustains at speed-up 1, each
#      flying (GUIDED, taken off, on its way to a point 5 km off) and sending
#      10 Hz telemetry: GLOBAL_POSITION_INT at 10 Hz; SYS_STATUS,
#      BATTERY_STATUS, MISSION_CURRENT, EXTENDED_SYS_STATE and HEARTBEAT at
#      1 Hz (15 frames a second each). MAVLink system ids stop at 254, so the
#      vehicles form fleets of 250, each sending to its own counting sink.
#      "Sustained": at least 99 % of the expected frames arrive and no vehicle
#      falls more than 100 ms behind the clock.
#   2. The fastest speed-up at which 10 vehicles, flying the same way and
#      talking to Dolphin's own ground station (link + vehicles, which ask for
#      their usual telemetry), stay in step with the clock: over 5 s, every
#      vehicle's time advances at least 99 % as much as the clock's, and the
#      lag (how far a vehicle is behind the clock when asked) stays under
#      250 ms of vehicle time (p99).
#
#   3. The same for ten of each other airframe (planes, rovers, boats,
#      submarines: 40 vehicles), each flying a mission in AUTO.
#
#   mix run bench/sim.exs        (make bench runs it too; BENCH_SIM_PART=2 or 3: from that part on)

alias Dolphin.{Clock, Sim}
alias Dolphin.MAVLink.Frame
alias Dolphin.MAVLink.Ardupilotmega, as: M

defmodule Bench.Sink do
  # Counts the frames (datagrams) that reach one UDP port, and tells vehicles what to do.
  def start do
    parent = self()
    pid = spawn_link(fn -> init(parent) end)
    receive do: ({:sink_port, ^pid, port} -> {pid, port})
  end

  def count(pid) do
    send(pid, {:count, self()})
    receive do: ({:count, ^pid, n} -> n)
  end

  def tell(pid, port, sysid, message), do: send(pid, {:tell, port, sysid, message})

  defp init(parent) do
    {:ok, socket} = :gen_udp.open(0, [:binary, active: 500, ip: {127, 0, 0, 1}, recbuf: 8 * 1024 * 1024])
    {:ok, port} = :inet.port(socket)
    send(parent, {:sink_port, self(), port})
    loop(socket, 0)
  end

  defp loop(socket, n) do
    receive do
      {:udp, ^socket, _, _, _} -> loop(socket, n + 1)
      {:udp_passive, ^socket} -> :inet.setopts(socket, active: 500) && loop(socket, n)
      {:count, from} -> send(from, {:count, self(), n}) && loop(socket, n)
      {:tell, port, sysid, message} ->
        :gen_udp.send(socket, {127, 0, 0, 1}, port, Frame.encode(%{message | target_system: sysid}, sysid: 255, compid: 190))
        loop(socket, n)
    end
  end
end

Code.require_file("os_process.exs", __DIR__)
cpu_ms = fn -> Bench.OSProcess.cpu_ms(System.pid()) end

command = fn command, params ->
  [p1, p2, p3, p4, p5, p6, p7] = Enum.map(params ++ List.duplicate(0, 7 - length(params)), &(&1 * 1.0))
  %M.CommandLong{target_component: 1, command: command, param1: p1, param2: p2, param3: p3, param4: p4, param5: p5, param6: p6, param7: p7}
end

home = %{lat: 40.444233, lon: -7.375234, alt: 820.0}
far = Dolphin.Sim.Copter.offset(home, 5_000, 3_000)

# Take off and head off, by commands as a ground station would give them.
fly = fn tell ->
  tell.(command.(176, [1, 4]))
  tell.(command.(400, [1]))
  tell.(command.(22, [0, 0, 0, 0, 0, 0, 30]))
end

head_off = fn tell -> tell.(command.(192, [-1, 0, 0, 0, far.lat, far.lon, 850])) end

IO.puts("simulator capacity (#{System.schedulers_online()} schedulers, OTP #{System.otp_release()})")
IO.puts("\n1. vehicles at speed-up 1, each flying and sending 15 frames/s (GLOBAL_POSITION_INT at 10 Hz)")

Clock.set_speedup(1)

for n <- if(System.get_env("BENCH_SIM_PART") in ["2", "3"], do: [], else: [250, 500, 1000, 1500]) do
  fleets = Enum.chunk_every(1..n, 250)

  vehicles =
    Enum.flat_map(fleets, fn chunk ->
      {sink, port} = Bench.Sink.start()

      for {i, sysid} <- Enum.with_index(chunk, 1) |> Enum.map(fn {i, k} -> {i, k} end) do
        spot = Dolphin.Sim.Copter.offset(home, div(i, 40) * 30.0, rem(i, 40) * 30.0)
        {:ok, pid} = Dolphin.Sim.Vehicle.start_link(sysid: sysid, gcs: {{127, 0, 0, 1}, port}, home: spot, register: false, config: %{ekf_ready_ms: 0})
        {:ok, info} = GenServer.call(pid, :info)
        {pid, sink, info.port, sysid}
      end
    end)

  tell = fn {_pid, sink, port, sysid}, message -> Bench.Sink.tell(sink, port, sysid, message) end

  for v <- vehicles do
    for {msgid, us} <- [{33, 100_000}, {1, 1_000_000}, {147, 1_000_000}, {42, 1_000_000}, {245, 1_000_000}], do: tell.(v, command.(511, [msgid, us]))
    fly.(&tell.(v, &1))
  end

  # Climb for a few seconds, then head off and measure.
  Process.sleep(3_000)
  for v <- vehicles, do: head_off.(&tell.(v, &1))
  Process.sleep(2_000)

  sinks = vehicles |> Enum.map(&elem(&1, 1)) |> Enum.uniq()
  before = Enum.sum(Enum.map(sinks, &Bench.Sink.count/1))
  cpu0 = cpu_ms.()
  t0 = System.monotonic_time(:millisecond)

  lags =
    for _ <- 1..10 do
      Process.sleep(1_000)
      vehicles |> Enum.map(fn {pid, _, _, _} -> {:ok, i} = GenServer.call(pid, :info, 30_000); i.lag_ms end) |> Enum.max()
    end

  elapsed = System.monotonic_time(:millisecond) - t0
  cpu = cpu_ms.() - cpu0
  frames = Enum.sum(Enum.map(sinks, &Bench.Sink.count/1)) - before
  expected = n * 15 * elapsed / 1000
  ratio = frames / expected
  sustained = ratio >= 0.99 and Enum.max(lags) <= 100

  IO.puts(
    "  #{String.pad_leading(Integer.to_string(n), 5)} vehicles: #{round(frames * 1000 / elapsed)} frames/s " <>
      "(#{Float.round(ratio * 100, 1)} % of #{round(expected * 1000 / elapsed)}), max lag #{Enum.max(lags)} ms, " <>
      "CPU #{round(cpu * 100 / elapsed)} % of one core#{if sustained, do: "", else: "  <- not sustained"}"
  )

  for {pid, _, _, _} <- vehicles, do: (Process.unlink(pid); Process.exit(pid, :kill))
end

# Over 5 s of real time: how far the slowest of `ids` kept the clock's pace,
# its lags behind the clock (sorted), and the CPU the VM used (% of one core).
# In step: every vehicle's time advanced as much as the clock's, and none is
# more than 5 steps (250 ms of vehicle time) behind it.
measure = fn ids ->
  times = fn -> Map.new(ids, fn id -> {:ok, i} = Sim.info(id); {id, i.time_ms} end) end
  cpu0 = cpu_ms.()
  t0 = System.monotonic_time(:millisecond)
  c0 = Clock.now_ms()
  v0 = times.()

  lags =
    for _ <- 1..25 do
      Process.sleep(200)
      Enum.map(ids, fn id -> {:ok, i} = Sim.info(id); i.lag_ms end)
    end
    |> List.flatten()
    |> Enum.sort()

  v1 = times.()
  clock = Clock.now_ms() - c0
  cpu = round((cpu_ms.() - cpu0) * 100 / (System.monotonic_time(:millisecond) - t0))
  pace = ids |> Enum.map(fn id -> (v1[id] - v0[id]) / clock end) |> Enum.min()
  p99 = Enum.at(lags, round(length(lags) * 0.99) - 1)
  %{pace: pace, p99: p99, max: List.last(lags), cpu: cpu, in_step: pace >= 0.99 and p99 <= 250}
end

IO.puts("\n2. 10 vehicles flying against Dolphin's ground station: max lag behind the clock")

{:ok, _} = Dolphin.Link.connect("udpin:127.0.0.1:0", name: "bench-sim")
port = Dolphin.Link.Connection.port("bench-sim")

for k <- if(System.get_env("BENCH_SIM_PART") == "3", do: [], else: [25, 50, 100, 200, 400, 800]) do
  Clock.set_speedup(k)
  {:ok, ids} = Sim.start(count: 10, gcs: port, ekf_ready_ms: 0)
  Enum.find_value(1..500, fn _ -> length(Dolphin.Vehicles.list() -- (Dolphin.Vehicles.list() -- ids)) == 10 || (Process.sleep(10) && nil) end)

  # As an operator would: retried until the vehicle takes it (a busy host loses some).
  retry = fn f -> Enum.find_value(1..50, fn _ -> match?({:ok, _}, f.()) || (Process.sleep(100) && nil) end) end

  for id <- ids do
    retry.(fn -> Dolphin.Vehicles.set_mode(id, :guided) end)
    retry.(fn -> Dolphin.Vehicles.arm(id) end)
    retry.(fn -> Dolphin.Vehicles.takeoff(id, 30) end)
  end

  Clock.sleep(15_000)
  for id <- ids, do: retry.(fn -> Dolphin.Vehicles.command_int(id, :mav_cmd_do_reposition, [-1, 0, 0, 0], {far.lat, far.lon, 30}) end)

  m = measure.(ids)
  {:ok, s} = Dolphin.Vehicles.state(hd(ids))

  IO.puts(
    "  speed-up #{String.pad_leading(Integer.to_string(k), 3)}: slowest vehicle ran at #{Float.round(m.pace * 100, 1)} % of the clock, " <>
      "lag p99 #{m.p99} ms / max #{m.max} ms of vehicle time, CPU #{m.cpu} % of one core, " <>
      "vehicle #{hd(ids)} at #{round(s.position.relative_alt)} m" <>
      if(m.in_step, do: "", else: "  <- not in step")
  )

  Sim.stop()
  # Forgotten, not just stopped: the next round's vehicles reuse the system
  # ids with new unique ids, and would be other vehicles ("1@...") beside these.
  Enum.each(ids, &Dolphin.Vehicles.forget/1)
end

IO.puts("\n3. ten of each other airframe (planes, rovers, boats, submarines: 40 vehicles) flying a mission, against Dolphin's ground station")

alias Dolphin.Mission.Command, as: C

# A mission each can fly from where it boots: a plane takes off and flies
# 5 km out; a rover or boat drives 5 km; a submarine dives to 5 m and goes 5 km.
far_mission = fn airframe, home ->
  home = Dolphin.Geo.location(home.lat, home.lon, home.alt)
  out = Dolphin.Geo.offset(home, 5_000, 3_000, 0)

  commands =
    case airframe do
      :plane -> [C.home(home), C.take_off(%{home | h: home.h + 80}), C.go_pos(%{out | h: home.h + 80})]
      :sub -> [C.home(home), C.go_pos(%{out | h: home.h - 5})]
      _ -> [C.home(home), C.go_pos(out)]
    end

  Dolphin.Mission.to_items(Dolphin.Mission.new("out", commands), airframe: airframe)
end

for k <- [25, 50, 100, 200] do
  Clock.set_speedup(k)
  # Submarines boot at the surface, at sea level.
  groups = [plane: 101, rover: 111, boat: 121, sub: 131]

  ids =
    Enum.flat_map(groups, fn {airframe, first} ->
      place = if airframe == :sub, do: %{home | alt: 0.0}, else: home
      {:ok, ids} = Sim.start(count: 10, first_sysid: first, gcs: port, ekf_ready_ms: 0, airframe: airframe, home: place)
      Enum.map(ids, &{&1, airframe})
    end)

  Enum.find_value(1..500, fn _ -> Enum.all?(ids, fn {id, _} -> match?({:ok, %{home: %{}}}, Dolphin.Vehicles.view(id)) end) || (Process.sleep(20) && nil) end)
  ok? = fn result -> match?({:ok, _}, result) or result == :ok end
  retry = fn f -> Enum.find_value(1..50, fn _ -> ok?.(f.()) || (Process.sleep(100) && nil) end) end

  ids
  |> Task.async_stream(
    fn {id, airframe} ->
      v = Enum.find_value(1..500, fn _ -> with({:ok, %{home: %{}} = v} <- Dolphin.Vehicles.view(id), do: v, else: (_ -> Process.sleep(20) && nil)) end)
      retry.(fn -> Dolphin.Vehicles.upload_mission(id, far_mission.(airframe, %{lat: v.home.lat, lon: v.home.lon, alt: v.home.h})) end)
      retry.(fn -> Dolphin.Vehicles.set_mode(id, :guided) end)
      retry.(fn -> Dolphin.Vehicles.arm(id) end)
      retry.(fn -> Dolphin.Vehicles.start_mission(id) end)
    end,
    max_concurrency: 10,
    timeout: :infinity
  )
  |> Stream.run()

  Clock.sleep(10_000)
  vehicles = Enum.map(ids, &elem(&1, 0))
  m = measure.(vehicles)
  # Armed: under way (a plane that reached its point at a high speed-up is circling home in RTL).
  flying = fn id -> match?({:ok, %{armed?: true}}, Dolphin.Vehicles.view(id)) end
  moving = Enum.count(vehicles, flying)
  left = for({id, airframe} <- ids, not flying.(id), do: airframe) |> Enum.frequencies() |> Enum.map_join(", ", fn {a, n} -> "#{n} #{a}" end)

  IO.puts(
    "  speed-up #{String.pad_leading(Integer.to_string(k), 3)}: #{moving} of 40 under way#{if left != "", do: " (not: #{left})"}, slowest vehicle ran at #{Float.round(m.pace * 100, 1)} % of the clock, " <>
      "lag p99 #{m.p99} ms / max #{m.max} ms of vehicle time, CPU #{m.cpu} % of one core" <>
      if(m.in_step, do: "", else: "  <- not in step")
  )

  Sim.stop()
  Enum.each(vehicles, &Dolphin.Vehicles.forget/1)
end
