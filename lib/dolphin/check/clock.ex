defmodule Dolphin.Check.Clock do
  @moduledoc false
  # The pre-flight check's time source: a virtual clock, independent of
  # `Dolphin.Clock`'s speed-up. Its time does not flow with real time: it
  # jumps to the next timer set on it once its dry run has nothing left to
  # do at the present time, so a dry run of a script's pauses, waits and
  # flights takes a moment, and what it finds does not depend on how busy
  # the machine is. (A clock of real time sped up would let every late step
  # of a loaded machine cost the dry run seconds of its time: conditions
  # would stop later, packs charge longer, the horizon come sooner.)
  #
  # One clock per dry run, each in the dry run's own instance
  # (`Dolphin.Instance`), so dry runs run side by side: a process reads the
  # clock of the instance it works in. The clock knows its dry run's
  # processes by their group leader: the dry run's caller makes the clock
  # its group leader (`within/2`) before it starts anything, so every
  # process the dry run starts inherits it (an engine run takes its
  # caller's); the clock passes their output on to the caller's own group
  # leader. "Nothing left to do" is then: each of those processes waits in
  # a `receive` with nothing it wants in its mailbox. The rest of the VM may
  # be as busy as it likes (other dry runs, other tests) without holding
  # this one up. A process of the dry run that never stops running (a busy
  # loop) cannot hold it for ever: after @patience_real_ms of it, time
  # moves on anyway.

  use GenServer

  @behaviour Dolphin.Engine.TimeSource

  # Slots of the :atomics array: the time now (clock ms), whether the horizon was reached.
  @now 1
  @ended 2
  @patience_real_ms 2_000
  # The VM not quiet for this long (real ms): something else keeps it busy.
  @busy_vm_ms 1
  # Nothing set on this clock and nothing running: the script may wait on
  # real time (a pick's timeout, which the fleet counts on Dolphin.Clock)
  # for this long before the dry run takes it for waiting for ever.
  @real_wait_ms 2_000

  @doc false
  # Runs `fun` (given no argument) with a clock of its own for instance
  # `instance` (one of a dry run's, which the caller works in), at time 0
  # and standing still until `run/2`; the caller, and every process started
  # from it meanwhile, belongs to the clock's dry run. `{:ok, result}`, or
  # `:taken` when another dry run holds that instance's clock.
  @spec within(atom(), (() -> result)) :: {:ok, result} | :taken when result: term()
  def within(instance, fun) do
    case GenServer.start_link(__MODULE__, instance, name: name(instance)) do
      {:ok, pid} ->
        original = Process.group_leader()
        Process.group_leader(self(), pid)

        try do
          {:ok, fun.()}
        after
          Process.group_leader(self(), original)
          Process.unlink(pid)
          GenServer.stop(pid)
        end

      {:error, {:already_started, _}} ->
        :taken
    end
  end

  @doc false
  # Runs `fun` (given no argument) with the clock of `within/2` moving, its
  # timers firing up to `horizon_ms`; returns what `fun` returns. `fun`
  # learns that the horizon was reached by the message {Dolphin.Check.Clock, :horizon}.
  @spec run(pos_integer(), (() -> result)) :: result when result: term()
  def run(horizon_ms, fun) do
    {name, _cells} = clock()
    :ok = GenServer.call(name, {:start, horizon_ms, self()}, :infinity)

    try do
      fun.()
    after
      # A clock busy asking a loaded VM's processes answers when it can.
      GenServer.call(name, :halt, :infinity)
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
    GenServer.cast(clock_name(), {:cancel, ref})
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

  defp name(instance), do: Module.concat(instance, __MODULE__)

  # The clock of the instance the caller works in: its name and its cells,
  # written once per instance name (dry runs' instance names are reused, so
  # there are as many as dry runs ever ran at once).
  defp clock do
    instance = Dolphin.Instance.current()

    case :persistent_term.get({__MODULE__, instance}, nil) do
      nil -> raise ArgumentError, "no dry run's clock in instance #{inspect(instance)}: Dolphin.Check.Clock serves dry runs only"
      clock -> clock
    end
  end

  defp clock_name, do: elem(clock(), 0)
  defp cells, do: elem(clock(), 1)

  defp schedule(pid, msg, ms, ref) do
    {name, cells} = clock()
    GenServer.cast(name, {:at, :atomics.get(cells, @now) + max(round(ms), 0), pid, msg, ref})
    ref
  end

  @impl GenServer
  def init(instance) do
    key = {__MODULE__, instance}

    cells =
      case :persistent_term.get(key, nil) do
        {_, cells} ->
          :atomics.put(cells, @now, 0)
          :atomics.put(cells, @ended, 0)
          cells

        nil ->
          cells = :atomics.new(2, signed: true)
          :persistent_term.put(key, {name(instance), cells})
          cells
      end

    {:ok, %{cells: cells, shared: shared_processes(), others: %{}, moving?: false, horizon: nil, owner: nil, timers: :gb_trees.empty(), refs: %{}, seq: 0, busy_since: nil, empty_since: nil}}
  end

  @impl GenServer
  def handle_call({:start, horizon_ms, owner}, _from, s), do: {:reply, :ok, %{s | moving?: true, horizon: horizon_ms, owner: owner}, 0}
  def handle_call(:halt, _from, s), do: {:reply, :ok, %{s | moving?: false}}

  @impl GenServer
  def handle_cast({:at, at, pid, msg, ref}, s) do
    key = {at, s.seq}
    next(%{s | timers: :gb_trees.insert(key, {pid, msg, ref}, s.timers), refs: Map.put(s.refs, ref, key), seq: s.seq + 1})
  end

  def handle_cast({:cancel, ref}, s) do
    case Map.pop(s.refs, ref) do
      {nil, _} -> next(s)
      {key, refs} -> next(%{s | timers: :gb_trees.delete_any(key, s.timers), refs: refs})
    end
  end

  # The dry run's processes write through their group leader, this clock:
  # their output goes where the caller's would (the I/O protocol's answer
  # goes straight back to the writer).
  @impl GenServer
  def handle_info({:io_request, _from, _reply_as, _request} = request, s) do
    send(Process.group_leader(), request)
    next(s)
  end

  # Nothing in the mailbox: move time on if the dry run is idle, else look again shortly.
  def handle_info(:timeout, s), do: advance(s)
  def handle_info(:look, s), do: advance(s)

  defp next(%{moving?: true} = s), do: {:noreply, s, 0}
  defp next(s), do: {:noreply, s}

  defp advance(%{moving?: false} = s), do: {:noreply, s}

  defp advance(s) do
    started = System.monotonic_time(:microsecond)
    real = div(started, 1000)
    {idle?, s} = idle(s, real)
    # Asking a busy VM's processes takes time: at most a third of this
    # clock's goes to it (the dry run's processes need the cores too).
    again_ms = max(1, div(System.monotonic_time(:microsecond) - started, 500))
    advance(s, idle?, real, again_ms)
  end

  defp advance(%{timers: timers} = s, idle?, real, again_ms) do
    ended? = :atomics.get(s.cells, @ended) == 1

    cond do
      not idle? and (s.busy_since == nil or real - s.busy_since < @patience_real_ms) ->
        look_again(again_ms, %{s | busy_since: s.busy_since || real})

      # What reached this clock before its dry run was idle (a timer set,
      # maybe sooner than the next; output a process waits on) is taken
      # first.
      Process.info(self(), :message_queue_len) != {:message_queue_len, 0} ->
        {:noreply, s, 0}

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

  # Nothing of the dry run runs or waits to run, and no module is being
  # loaded (for the dry run, maybe: the loader reads the file in native
  # code, during which it and the process waiting for it look idle).
  #
  # On a quiet VM nothing is ready to run but this clock: asked at once,
  # as the last timer's process is sent its message, the VM's count says
  # so; the dry run's processes tell the clock when they set a timer, and
  # it asks again. On a VM busy with something else (not quiet for
  # @busy_vm_ms), the dry run's processes (their
  # group leader is this clock) are asked, and so are those that serve
  # every process: the runtime's own (the logger, :global) and the
  # application's outside any instance (the engine's registry, the
  # scripts' and runs' supervisors). Asked one by one, they are not seen at
  # one moment: the VM is asked twice, and only if the second round finds
  # the same processes, none of which ran in between (its reductions
  # unchanged), were they all waiting at once, between the two rounds. The
  # second round lists the VM's processes anew: a process started during
  # the first, after its list was taken, by one asked later and found
  # waiting (for that start to finish) would be missed by asking the first
  # round's processes again — a stand-in flight not yet run, its start time
  # not yet read, while time moved on (seen beside busy loops: a Flight
  # started that way once or twice a run of three dry runs side by side).
  defp idle(s, real) do
    quiet? = :erlang.statistics(:total_active_tasks) <= 1

    cond do
      loading?() -> {false, s}
      quiet? -> {true, s}
      s.busy_since == nil or real - s.busy_since < @busy_vm_ms -> {false, s}
      true -> with({idle?, others} <- dry_run_waiting?(s.shared, s.others), do: {idle?, %{s | others: others}})
    end
  end

  defp loading? do
    Process.info(Process.whereis(:code_server), [:status, :current_function]) != [status: :waiting, current_function: {:code_server, :loop, 1}] or
      Process.info(Process.whereis(:erl_prim_loader), [:status, :current_function]) != [status: :waiting, current_function: {:erl_prim_loader, :loop, 3}]
  end

  # {idle?, the processes known to be none of the above}.
  defp dry_run_waiting?(shared, others) do
    case waiting(shared, others) do
      {:busy, others} ->
        {false, others}

      {first, others} ->
        case waiting(shared, others) do
          {:busy, others} -> {false, others}
          {second, others} -> {Enum.sort(second) == Enum.sort(first), others}
        end
    end
  end

  # The reductions of the processes above, all waiting ({pid, reductions}),
  # or :busy; and the processes known to be none of them: each of the rest
  # of the VM is asked once it is seen waiting (a process takes its group
  # leader as it starts, and keeps it).
  defp waiting(shared, others) do
    me = self()
    pids = Process.list()
    others = if map_size(others) > 2 * length(pids), do: Map.take(others, pids), else: others

    Enum.reduce_while(pids, {[], others}, fn pid, {acc, others} ->
      if pid == me or is_map_key(others, pid) do
        {:cont, {acc, others}}
      else
        case Process.info(pid, [:group_leader, :status, :reductions]) do
          [group_leader: gl, status: status, reductions: reductions] when gl == me or is_map_key(shared, gl) or is_map_key(shared, pid) ->
            if status == :waiting, do: {:cont, {[{pid, reductions} | acc], others}}, else: {:halt, {:busy, others}}

          [group_leader: _, status: :waiting, reductions: _] ->
            {:cont, {acc, Map.put(others, pid, true)}}

          _ ->
            {:cont, {acc, others}}
        end
      end
    end)
  end

  # The group leaders of the runtime's own processes, and the application's
  # processes outside any instance (not what its dynamic supervisors hold:
  # those run on someone's behalf and take their group leader).
  defp shared_processes do
    runtime = for name <- [:init, :erl_prim_loader, :code_server, :logger, :global_name_server], pid = Process.whereis(name), {:group_leader, gl} <- [Process.info(pid, :group_leader)], do: gl

    application = if sup = Process.whereis(Dolphin.Supervisor), do: static_tree(sup), else: []
    Map.new(runtime ++ application, &{&1, true})
  end

  # A supervisor and what it holds, but an instance's tree and what a
  # dynamic supervisor holds (its children have no id).
  defp static_tree(sup) do
    [
      sup
      | for {id, pid, type, _} <- Supervisor.which_children(sup), is_pid(pid), id != :undefined, not match?({Dolphin.Instance, _}, id), reduce: [] do
          acc -> if(type == :supervisor, do: static_tree(pid), else: [pid]) ++ acc
        end
    ]
  end
end
