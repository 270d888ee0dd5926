# The runtime's floor under bench/reaction.exs's burst: what 1,000 stops cost
# on this machine with none of Dolphin's work in them.
#
# 1,000 bare GenServers stand for 1,000 platform tasks, each linked to a
# process that traps exits (a leaf). One process, at high priority for the
# burst as Dolphin.Engine.Conditions is, sends each a stop in the shape of a
# GenServer call (what Dolphin.Engine.Stops sends); each notes the moment it
# handles it (where bench/reaction.exs takes its time: the stop callback)
# and replies. Measured from the first send: when each stop was handled,
# over 10 bursts, in two cases:
#
#   ends:  each process then ends, as a platform task does once stopped
#          (Dolphin.Engine.FakePlatform, a mission task): its exit, the
#          exit signal to its linked process, and that process's wake-up
#          are what the runtime does for every stop, in the same run queues
#          as the stops not yet handled;
#   stays: each replies and waits on (no exit): the messages alone.
#
# No condition is evaluated, no table read, no leaf, `until` or event woken:
# bench/reaction.exs's "all 1000 at once" can come down to this and no
# further on the same machine with a process per platform task.
#
#   MIX_ENV=prod mix run bench/reaction_floor.exs

Code.require_file("percentiles.exs", __DIR__)

defmodule Bench.ReactionFloor do
  defmodule Task do
    @moduledoc false
    use GenServer

    @impl true
    def init({notify, mode}), do: {:ok, {notify, mode}}

    @impl true
    def handle_call({:stop, _reason}, _from, {notify, mode} = s) do
      send(notify, {:stopped, System.monotonic_time()})
      if mode == :ends, do: {:stop, :normal, :ok, s}, else: {:reply, :ok, s}
    end
  end

  @n 1_000

  # One burst: {µs from the first send to each stop, µs the sends took}.
  def burst(mode) do
    me = self()
    # The linked process (a leaf) starts the tasks, linked to it, as a leaf
    # starts its platform task; it traps exits and takes whatever comes.
    leaf =
      spawn(fn ->
        Process.flag(:trap_exit, true)
        send(me, {:tasks, for(_ <- 1..@n, do: elem(GenServer.start_link(Task, {me, mode}), 1))})
        leaf_loop()
      end)

    tasks = receive(do: ({:tasks, tasks} -> tasks))
    # Steady state, as bench/reaction.exs waits for its run.
    Process.sleep(20)

    Process.flag(:priority, :high)
    t0 = System.monotonic_time()
    for pid <- tasks, do: send(pid, {:"$gen_call", {leaf, make_ref()}, {:stop, :condition_met}})
    sent = System.monotonic_time()
    Process.flag(:priority, :normal)

    stops = for _ <- tasks, do: receive(do: ({:stopped, t} -> us(t - t0)))
    Process.exit(leaf, :kill)
    for pid <- tasks, do: Process.exit(pid, :kill)
    {stops, us(sent - t0)}
  end

  defp leaf_loop do
    receive do
      _ -> leaf_loop()
    end
  end

  defp us(native), do: System.convert_time_unit(native, :native, :microsecond)

  def row(label, %{n: n, p50: p50, p99: p99, max: max}, extra),
    do: IO.puts(String.pad_trailing(label, 34) <> String.pad_leading("#{n}", 8) <> String.pad_leading("#{p50} µs", 12) <> String.pad_leading("#{p99} µs", 12) <> String.pad_leading("#{max} µs", 12) <> "   " <> extra)
end

IO.puts("reaction floor: 1,000 bare processes stopped at once (#{System.schedulers_online()} schedulers, OTP #{System.otp_release()}, Elixir #{System.version()})")
IO.puts(String.pad_trailing("", 34) <> String.pad_leading("samples", 8) <> String.pad_leading("p50", 12) <> String.pad_leading("p99", 12) <> String.pad_leading("max", 12))

# Warm-up (code loading, first allocations).
Bench.ReactionFloor.burst(:ends)

for mode <- [:ends, :stays] do
  runs = for _ <- 1..10, do: Bench.ReactionFloor.burst(mode)
  sends = runs |> Enum.map(&elem(&1, 1)) |> Enum.sort() |> Enum.at(5)
  label = if mode == :ends, do: "each then ends (a platform task)", else: "each replies and stays"
  Bench.ReactionFloor.row(label, Bench.Percentiles.of(Enum.flat_map(runs, &elem(&1, 0))), "(10 bursts; the 1,000 sends took #{sends} µs, median)")
end
