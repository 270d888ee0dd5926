defmodule Dolphin.Check.Clock do
  @moduledoc false
  # The pre-flight check's time source: a virtual clock, independent of
  # `Dolphin.Clock`'s speed-up. Its time does not flow with real time: it
  # jumps to the next timer set on it once the VM has nothing left to do at
  # the present time (no process running or waiting to run but this clock),
  # so a dry run of a script's pauses, waits and flights takes a moment,
  # and what it finds does not depend on how busy the machine is. (A clock
  # of real time sped up would let every late step of a loaded machine cost
  # the dry run seconds of its time: conditions would stop later, packs
  # charge longer, the horizon come sooner.)
  #
  # One dry run at a time per VM (`run/2`): the clock is a registered
  # process, its time and its horizon in an :atomics array that any process
  # reads. Something else in the VM that keeps running (another test's busy
  # process) cannot hold the dry run for ever: after @patience_real_ms of
  # it, time moves on anyway.

  use GenServer

  @behaviour Dolphin.Engine.TimeSource

  @name __MODULE__
  @cells {__MODULE__, :cells}
  # Slots of the :atomics array: the time now (clock ms), whether the horizon was reached.
  @now 1
  @ended 2
  @patience_real_ms 2_000
  # Nothing set on this clock and nothing running: the script may wait on
  # real time (a pick's timeout, which the fleet counts on Dolphin.Clock)
  # for this long before the dry run takes it for waiting for ever.
  @real_wait_ms 2_000

  @doc false
  # Runs `fun` (given no argument) with this clock at time 0, its timers
  # firing up to `horizon_ms`; returns what `fun` returns. `fun` learns that
  # the horizon was reached by the message {Dolphin.Check.Clock, :horizon}.
  @spec run(pos_integer(), (-> result)) :: result when result: term()
  def run(horizon_ms, fun) do
    {:ok, pid} = start(horizon_ms, self())

    try do
      fun.()
    after
      GenServer.stop(pid)
    end
  end

  # Another dry run holds the clock: wait for its end.
  defp start(horizon_ms, owner) do
    case GenServer.start(__MODULE__, {horizon_ms, owner}, name: @name) do
      {:ok, pid} ->
        {:ok, pid}

      {:error, {:already_started, other}} ->
        ref = Process.monitor(other)

        receive do
          {:DOWN, ^ref, :process, _, _} -> start(horizon_ms, owner)
        end
    end
  end

  @doc false
  @spec horizon_reached?() :: boolean()
  def horizon_reached?, do: :atomics.get(cells(), @ended) == 1

  @impl Dolphin.Engine.TimeSource
  def now_ms, do: :atomics.get(cells(), @now)

  @impl Dolphin.Engine.TimeSource
  def send_after(pid, msg, ms), do: schedule(pid, msg, ms, make_ref())

  @impl Dolphin.Engine.TimeSource
  def cancel(ref) do
    GenServer.cast(@name, {:cancel, ref})
    :ok
  end

  @impl Dolphin.Engine.TimeSource
  def sleep(ms) do
    ref = make_ref()
    schedule(self(), {__MODULE__, :wake, ref}, ms, ref)

    receive do
      {__MODULE__, :wake, ^ref} -> :ok
    end
  end

  # Bounds (not timers): real time, generous (the dry run's vehicles answer
  # at once, but the machine may be loaded).
  @impl Dolphin.Engine.TimeSource
  def real_ms(_ms), do: 5_000

  defp cells, do: :persistent_term.get(@cells)

  defp schedule(pid, msg, ms, ref) do
    GenServer.cast(@name, {:at, now_ms() + max(round(ms), 0), pid, msg, ref})
    ref
  end

  @impl GenServer
  def init({horizon_ms, owner}) do
    cells = :atomics.new(2, signed: true)
    # Written once per dry run: the array itself changes, not the term.
    :persistent_term.put(@cells, cells)
    {:ok, %{cells: cells, horizon: horizon_ms, owner: owner, timers: :gb_trees.empty(), refs: %{}, seq: 0, busy_since: nil, empty_since: nil}, 0}
  end

  @impl GenServer
  def handle_cast({:at, at, pid, msg, ref}, s) do
    key = {at, s.seq}
    {:noreply, %{s | timers: :gb_trees.insert(key, {pid, msg, ref}, s.timers), refs: Map.put(s.refs, ref, key), seq: s.seq + 1}, 0}
  end

  def handle_cast({:cancel, ref}, s) do
    case Map.pop(s.refs, ref) do
      {nil, _} -> {:noreply, s, 0}
      {key, refs} -> {:noreply, %{s | timers: :gb_trees.delete_any(key, s.timers), refs: refs}, 0}
    end
  end

  # Nothing in the mailbox: move time on if the VM is idle, else look again shortly.
  @impl GenServer
  def handle_info(:timeout, s), do: advance(s)
  def handle_info(:look, s), do: advance(s)

  defp advance(%{timers: timers} = s) do
    real = System.monotonic_time(:millisecond)

    ended? = :atomics.get(s.cells, @ended) == 1

    cond do
      not idle?() and (s.busy_since == nil or real - s.busy_since < @patience_real_ms) ->
        look_again(1, %{s | busy_since: s.busy_since || real})

      # Nothing set on this clock: the script waits on something else (a
      # pick), or has ended. After a while of real time, for ever.
      :gb_trees.is_empty(timers) ->
        since = s.empty_since || real

        cond do
          ended? -> {:noreply, %{s | empty_since: nil}}
          real - since >= @real_wait_ms -> {:noreply, %{horizon(s) | empty_since: nil}}
          true -> look_again(10, %{s | empty_since: since})
        end

      true ->
        {{at, _} = key, {pid, msg, ref}} = :gb_trees.smallest(timers)
        # Past the horizon the owner is told once; time still moves, so
        # that the script's stop, which waits on this clock too, completes.
        s = if at > s.horizon and not ended?, do: horizon(s), else: s
        if at > :atomics.get(s.cells, @now), do: :atomics.put(s.cells, @now, at)
        send(pid, msg)
        {:noreply, %{s | timers: :gb_trees.delete(key, timers), refs: Map.delete(s.refs, ref), busy_since: nil, empty_since: nil}, 0}
    end
  end

  defp horizon(s) do
    :atomics.put(s.cells, @now, max(:atomics.get(s.cells, @now), s.horizon))
    :atomics.put(s.cells, @ended, 1)
    send(s.owner, {__MODULE__, :horizon})
    s
  end

  defp look_again(real_ms, s) do
    Process.send_after(self(), :look, real_ms)
    {:noreply, s}
  end

  # Nothing runs or waits to run on the VM's schedulers but this process.
  defp idle?, do: :erlang.statistics(:total_active_tasks) <= 1
end
