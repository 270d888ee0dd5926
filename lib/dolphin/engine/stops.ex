defmodule Dolphin.Engine.Stops do
  @moduledoc false
  # The platform tasks running now whose stop another process than their
  # leaf may send: a table (public, one per node, made by
  # Dolphin.Engine.Supervisor) of {task_id, platform_pid, leaf_pid, alias,
  # platform_module, run_id}, one row per leaf whose platform answers a stop
  # request (Dolphin.Engine.Platform.stop_request/1). A run's rows go when
  # it ends, whatever became of its leaves.
  #
  # Why: a burst of conditions tripped by one change. A run's conditions
  # process (Dolphin.Engine.Conditions) evaluates the `until`s' conditions;
  # when one holds, it sends the stop to every platform under that `until`
  # itself, straight from where the condition was found true, before any
  # `until` or leaf is woken: one process wake-up per stop instead of three.
  #
  # The stop is sent once: whoever takes a task's row (`claim/1` by the leaf,
  # `stop_under/3` by the conditions process; :ets.take/2 is atomic) sends it.
  # The reply goes to the leaf's alias whoever sent the request, so the leaf
  # always learns its platform's answer; a leaf whose row was taken by
  # someone else waits for that answer (`await/4`) instead of asking again,
  # and the vehicle is held once.

  @table __MODULE__

  @doc false
  # Made once per node by the engine's supervisor (which owns it). Without
  # write_concurrency: its rows are written as leaves start and end, while
  # a burst's stops walk it; a plain ordered_set walks about twice as fast.
  def new do
    if :ets.whereis(@table) == :undefined,
      do: :ets.new(@table, [:named_table, :public, :ordered_set])

    :ok
  end

  @doc false
  # A leaf's platform started: it may be stopped from outside. Returns the
  # alias the platform's reply to a stop comes to.
  def register(task_id, platform_pid, platform, run_id) do
    alias = :erlang.alias()
    :ets.insert(@table, {task_id, platform_pid, self(), alias, platform, run_id})
    alias
  end

  @doc false
  # A run has ended: no row of it stays (a leaf that crashed left its own).
  def forget_run(run_id) do
    :ets.match_delete(@table, {:_, :_, :_, :_, :_, run_id})
    :ok
  end

  @doc false
  # The leaf takes its row back to stop its platform itself: true if nobody
  # had sent the stop yet (the leaf sends it), false if someone had.
  def claim(task_id), do: :ets.take(@table, task_id) != []

  @doc false
  # The platform has ended (reported, or exited): nothing to stop any more.
  def forget(task_id, alias) do
    :ets.delete(@table, task_id)
    if alias, do: :erlang.unalias(alias)
    :ok
  end

  @doc false
  # Whether a stop was sent to the task's platform by someone else (its row is gone).
  def sent?(task_id), do: not :ets.member(@table, task_id)

  @doc false
  # Sends a stop (`reason`) to the platform of every task `first < id <=
  # last` whose row is still there (the tasks under the node `first`: ids
  # are given in pre-order, a subtree's are one interval). Returns how many.
  def stop_under(first, last, reason), do: stop_from(:ets.next(@table, first), last, reason, 0)

  defp stop_from(id, last, reason, n) when is_integer(id) and id <= last do
    next = :ets.next(@table, id)

    case :ets.take(@table, id) do
      [{^id, pid, leaf, alias, platform, _run} = row] ->
        case request(platform, reason) do
          {:ok, request} ->
            send(pid, {:"$gen_call", {leaf, [:alias | alias]}, request})
            stop_from(next, last, reason, n + 1)

          # The leaf asks itself, and meets the error where it always did.
          :error ->
            :ets.insert(@table, row)
            stop_from(next, last, reason, n)
        end

      [] ->
        stop_from(next, last, reason, n)
    end
  end

  defp stop_from(_id, _last, _reason, n), do: n

  defp request(platform, reason) do
    {:ok, platform.stop_request(reason)}
  catch
    _kind, _why -> :error
  end

  @doc false
  # The leaf's wait for the answer to a stop someone else sent (bounded,
  # real ms): the reply, or :gone when the process ended before answering
  # (it had finished or failed: counted as stopped, as a leaf's own request
  # does), or :timeout.
  def await(pid, alias, bound) do
    mon = Process.monitor(pid)

    receive do
      {[:alias | ^alias], reply} ->
        Process.demonitor(mon, [:flush])
        {:reply, reply}

      {:DOWN, ^mon, :process, ^pid, _} ->
        # A reply sent just before the exit is there already.
        receive do
          {[:alias | ^alias], reply} -> {:reply, reply}
        after
          0 -> :gone
        end
    after
      bound ->
        Process.demonitor(mon, [:flush])
        :timeout
    end
  end
end
