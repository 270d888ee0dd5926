# Reaction of the engine to telemetry: the latency from a vehicle state change
# that makes a condition true to the stop callback of the platform task that
# condition ends — until(task, battery(v) < 0.3) — with 1, 100 and 1,000
# such conditions running at the same time.
#
#   one of N:  N untils, each on its own (fake) vehicle and condition; the
#              battery of one vehicle drops; time until its task's stop
#              callback runs (the others keep running). Many samples.
#   all N:     N untils all reading the same vehicle, whose battery drops:
#              time until each of the N stop callbacks (a burst); ten
#              bursts, their stops together, and the CPU time of each.
#              With one scheduler (ERL_FLAGS="+S 1:1") that CPU time is the
#              work itself; with two it includes the schedulers' spinning.
#
# The vehicles are Dolphin.Fleet.FakeSource fakes: the change is published on
# Dolphin.PubSub exactly as a real vehicle's telemetry is, so this measures
# the engine (pub/sub, condition re-evaluation in the until's process, the
# stop travelling to the leaf, the platform's stop callback), not the radio.
#
#   MIX_ENV=prod mix run bench/reaction.exs

alias Dolphin.Engine
alias Dolphin.Engine.{Cond, Context, FakePlatform}
alias Dolphin.Fleet.FakeSource

source = :bench_fakes
fleet = :bench_fleet
{:ok, _} = FakeSource.start_link(name: source, events: false)
{:ok, _} = Dolphin.Fleet.start_link(name: fleet, source: FakeSource.source(source), events: false)
Context.put(%Context{fleet: fleet, source: FakeSource.source(source), owner: self()})

max_n = 1_000
ids = Enum.map(1..max_n, &(10_000 + &1))
shared = 20_000
for id <- [shared | ids], do: FakeSource.add(source, id, type: :uav, battery: 1.0)
{:ok, _} = Dolphin.Fleet.pick(fleet, self(), id: ids, count: max_n, timeout: 10_000)

Code.require_file("percentiles.exs", __DIR__)

defmodule Bench do
  def low(v), do: Cond.new(fn snap -> Dolphin.Engine.Snapshot.battery(snap, v) < 0.3 end, source: "battery(v) < 0.3")

  # N untils, task i on vehicle i, condition on cond_vehicle.(i); returns the run once all tasks run.
  def start(n, ids, cond_vehicle) do
    tasks =
      for {v, i} <- Enum.with_index(Enum.take(ids, n)) do
        task = FakePlatform.task("t#{i}", duration: :infinity, notify: self())
        Engine.on(Engine.until(task, low(cond_vehicle.(i, v))), [v])
      end

    {:ok, run} = Engine.start(Engine.concurrent(tasks))
    for _ <- 1..n, do: receive(do: ({:fake_platform, :started, _} -> :ok))
    # Steady state: the run has started (its processes spawned, their first
    # garbage collections done) before anything is measured.
    Process.sleep(20)
    run
  end

  def finish(run, source, ids) do
    # (A run whose conditions all held has ended already.)
    _ = Engine.stop(run)
    {:ok, _} = Engine.await(run, 60_000)
    flush()
    for id <- ids, do: FakeSource.set(source, id, battery: 1.0)
  end

  def flush do
    receive do
      {:fake_platform, _, _} -> flush()
    after
      100 -> :ok
    end
  end

  def us(native), do: System.convert_time_unit(native, :native, :microsecond)

  def stats(samples), do: Bench.Percentiles.of(samples)

  def row(label, %{n: n, p50: p50, p99: p99, max: max}),
    do: IO.puts(String.pad_trailing(label, 34) <> String.pad_leading("#{n}", 8) <> String.pad_leading("#{p50} µs", 12) <> String.pad_leading("#{p99} µs", 12) <> String.pad_leading("#{max} µs", 12))
end

# One of N: drop the battery of one vehicle at a time, in random order.
one_of = fn n, samples ->
  run = Bench.start(n, ids, fn _i, v -> v end)

  latencies =
    ids
    |> Enum.take(n)
    |> Enum.with_index()
    |> Enum.shuffle()
    |> Enum.take(samples)
    |> Enum.map(fn {v, i} ->
      name = "t#{i}"
      t0 = System.monotonic_time()
      FakeSource.set(source, v, battery: 0.2)

      receive do
        {:fake_platform, :stopped, %{name: ^name, at: t1}} -> Bench.us(t1 - t0)
      end
    end)

  Bench.finish(run, source, Enum.take(ids, n))
  latencies
end

# All N: every until reads the same vehicle. Also returns the CPU time the
# VM used from the change to the last stop (all its threads: with more than
# one scheduler, their spinning before they sleep is in it too).
all_n = fn n ->
  run = Bench.start(n, ids, fn _i, _v -> shared end)
  {cpu0, _} = :erlang.statistics(:runtime)
  t0 = System.monotonic_time()
  FakeSource.set(source, shared, battery: 0.2)
  latencies = for _ <- 1..n, do: receive(do: ({:fake_platform, :stopped, %{at: t1}} -> Bench.us(t1 - t0)))
  {cpu1, _} = :erlang.statistics(:runtime)
  Bench.finish(run, source, [shared])
  {latencies, cpu1 - cpu0}
end

# Bursts of N, one after another: every stop of all of them, and the CPU
# milliseconds of each burst.
bursts = fn n, times ->
  runs = for _ <- 1..times, do: all_n.(n)
  {Enum.flat_map(runs, &elem(&1, 0)), Enum.map(runs, &elem(&1, 1))}
end

IO.puts("reaction: state change -> stop callback (#{System.schedulers_online()} schedulers, OTP #{System.otp_release()}, Elixir #{System.version()})")
IO.puts(String.pad_trailing("", 34) <> String.pad_leading("samples", 8) <> String.pad_leading("p50", 12) <> String.pad_leading("p99", 12) <> String.pad_leading("max", 12))

# Warm-up (code loading, first allocations).
one_of.(10, 10)
all_n.(10)
median = fn list -> Enum.at(Enum.sort(list), div(length(list), 2)) end

Bench.row("1 condition", Bench.stats(Enum.flat_map(1..300, fn _ -> one_of.(1, 1) end)))
Bench.row("one of 100 concurrent conditions", Bench.stats(one_of.(100, 100)))
Bench.row("one of 1000 concurrent conditions", Bench.stats(Enum.flat_map(1..2, fn _ -> one_of.(1000, 300) end)))
{stops, cpu} = bursts.(100, 10)
Bench.row("all 100 at once (one vehicle)", Bench.stats(stops))
IO.puts("  (10 bursts; CPU per burst, median: #{median.(cpu)} ms)")
{stops, cpu} = bursts.(1000, 10)
Bench.row("all 1000 at once (one vehicle)", Bench.stats(stops))
IO.puts("  (10 bursts; CPU per burst, median: #{median.(cpu)} ms)")
