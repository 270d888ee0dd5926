defmodule Dolphin.Test.ManualClock do
  @moduledoc """
  A `Dolphin.Engine.TimeSource` that only moves when told: the engine's
  timers queue here, ordered by due time and then by the order they were set,
  and `step/0` fires the next one after the engine has settled (every engine
  process idle). So a run's whole sequence of events is reproducible — what the
  property tests compare with the reference interpreter.

      {:ok, _} = Dolphin.Test.ManualClock.start_link()
      {:ok, run} = Dolphin.Engine.start(task, clock: Dolphin.Test.ManualClock)
      result = Dolphin.Test.ManualClock.run_until(fn -> ... end)

  One at a time (a named process): tests that use it are not async.
  """

  @behaviour Dolphin.Engine.TimeSource

  use GenServer

  @table __MODULE__

  def start_link(_opts \\ []), do: GenServer.start_link(__MODULE__, :ok, name: __MODULE__)

  def child_spec(opts), do: %{id: __MODULE__, start: {__MODULE__, :start_link, [opts]}}

  # --- time source ---

  @impl Dolphin.Engine.TimeSource
  def now_ms, do: :ets.lookup_element(@table, :now, 2)

  @impl Dolphin.Engine.TimeSource
  def send_after(pid, msg, ms), do: GenServer.call(__MODULE__, {:after, {:send, pid, msg}, ms})

  @impl Dolphin.Engine.TimeSource
  def cancel(ref), do: GenServer.call(__MODULE__, {:cancel, ref})

  @impl Dolphin.Engine.TimeSource
  def sleep(ms) do
    ref = make_ref()
    send_after(self(), {__MODULE__, ref}, ms)
    receive do: ({__MODULE__, ^ref} -> :ok)
  end

  # Bounds in real time: the manual clock does not move while the engine stops things.
  @impl Dolphin.Engine.TimeSource
  def real_ms(_ms), do: 10_000

  # --- driving it ---

  @doc "Back to time 0 with no timer."
  def reset, do: GenServer.call(__MODULE__, :reset)

  @doc "Runs `fun` (in the driving process) when the clock reaches `at_ms`; set before the run, such timers come first at equal times."
  def at(at_ms, fun), do: GenServer.call(__MODULE__, {:at, {:call, fun}, at_ms})

  @doc "Waits until the engine settles, then fires the next timer; `:empty` when none is left."
  def step do
    settle()

    case GenServer.call(__MODULE__, :pop) do
      :empty -> :empty
      {:send, pid, msg} -> send(pid, msg) && :ok
      {:call, fun} -> fun.() && :ok
    end
  end

  @doc """
  Steps until `done` (a function returning `{:ok, value}` or nil, checked
  after each settle) gives a value, and returns `{:ok, value}`; returns
  `:stuck` when no timer is left before `horizon` (clock ms) and not done.
  """
  def run_until(done, horizon \\ :infinity, max \\ 100_000) do
    settle()

    case done.() do
      {:ok, value} ->
        {:ok, value}

      nil when max == 0 ->
        raise "ManualClock: still not done after the step limit"

      nil ->
        case GenServer.call(__MODULE__, :next_due) do
          due when due == nil or (horizon != :infinity and due > horizon) ->
            :stuck

          _ ->
            step()
            run_until(done, horizon, max - 1)
        end
    end
  end

  @doc """
  Waits until every engine process (node, run, user code, fake platform task,
  fleet, fake source, this clock) is idle with an empty mailbox, three checks
  in a row.
  """
  def settle(tries \\ 50_000), do: settle(tries, 0)

  defp settle(0, _quiet), do: raise("ManualClock: the engine never settled: #{inspect(busy())}")
  defp settle(_tries, 3), do: :ok

  defp settle(tries, quiet) do
    if busy() == [] do
      :erlang.yield()
      settle(tries - 1, quiet + 1)
    else
      Process.sleep(1)
      settle(tries - 1, 0)
    end
  end

  # Engine processes that are running, have messages to handle, or wait for
  # the code server (loading a module: not idle, though blocked).
  defp busy do
    me = self()

    for pid <- Process.list(),
        pid != me,
        not idle?(Process.info(pid, [:status, :message_queue_len, :current_function])),
        relevant?(pid),
        do: pid
  end

  defp idle?(nil), do: true
  defp idle?(status: :waiting, message_queue_len: 0, current_function: {m, _, _}), do: m != :code_server
  defp idle?(_), do: false

  # A process that works for runs on this clock. One spawned a moment ago and
  # not run yet has an empty dictionary (proc_lib fills it in the new process):
  # it works for whoever spawned it. A loaded machine can leave such a process
  # waiting for a scheduler while the engine looks idle, and without this the
  # next timer would fire before it ran.
  defp relevant?(pid, depth \\ 0) do
    case Process.info(pid, [:dictionary, :parent]) do
      [dictionary: [], parent: parent] when is_pid(parent) and depth < 8 ->
        relevant?(parent, depth + 1)

      [dictionary: dict, parent: _] ->
        case List.keyfind(dict, :"$dolphin_context", 0) do
          {_, %{clock: __MODULE__}} ->
            true

          _ ->
            case List.keyfind(dict, :"$initial_call", 0) do
              {_, {m, _, _}} -> m in [Dolphin.Engine.Runner, Dolphin.Engine.Run, Dolphin.Engine.FakePlatform, Dolphin.Fleet, Dolphin.Fleet.FakeSource, __MODULE__]
              _ -> false
            end
        end

      nil ->
        false
    end
  end

  # --- server ---

  @impl GenServer
  def init(:ok) do
    :ets.new(@table, [:named_table, :public, read_concurrency: true])
    :ets.insert(@table, {:now, 0})
    {:ok, %{seq: 0, timers: :gb_trees.empty(), refs: %{}}}
  end

  @impl GenServer
  def handle_call(:reset, _from, _s) do
    :ets.insert(@table, {:now, 0})
    {:reply, :ok, %{seq: 0, timers: :gb_trees.empty(), refs: %{}}}
  end

  def handle_call({:after, action, ms}, _from, s), do: add(s, now_ms() + max(ms, 0), action)
  def handle_call({:at, action, at}, _from, s), do: add(s, max(at, now_ms()), action)

  def handle_call({:cancel, ref}, _from, s) do
    case Map.pop(s.refs, ref) do
      {nil, _} -> {:reply, :ok, s}
      {key, refs} -> {:reply, :ok, %{s | refs: refs, timers: :gb_trees.delete_any(key, s.timers)}}
    end
  end

  def handle_call(:next_due, _from, s) do
    if :gb_trees.is_empty(s.timers),
      do: {:reply, nil, s},
      else: {:reply, s.timers |> :gb_trees.smallest() |> elem(0) |> elem(0), s}
  end

  def handle_call(:pop, _from, s) do
    if :gb_trees.is_empty(s.timers) do
      {:reply, :empty, s}
    else
      {{due, _seq}, {ref, action}, timers} = :gb_trees.take_smallest(s.timers)
      :ets.insert(@table, {:now, due})
      {:reply, action, %{s | timers: timers, refs: Map.delete(s.refs, ref)}}
    end
  end

  defp add(s, due, action) do
    ref = make_ref()
    key = {due, s.seq}
    {:reply, ref, %{s | seq: s.seq + 1, timers: :gb_trees.insert(key, {ref, action}, s.timers), refs: Map.put(s.refs, ref, key)}}
  end
end
