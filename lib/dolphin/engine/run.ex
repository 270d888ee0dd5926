defmodule Dolphin.Engine.Run do
  @moduledoc false
  # One process per run (one `execute`): allocates the vehicles, is the parent
  # of the root task node, and answers the caller. It lives under
  # Dolphin.Engine.Runs and is linked to its caller: when the caller dies (a
  # script stopped, killed) the run stops its tree — every platform task gets
  # its stop callback — before it exits. A proc_lib process with full :sys
  # support; its :sys parent is its supervisor, handed over by start_link/1.

  alias Dolphin.Engine.{Conditions, Context, On, PlatformTask, Runner, Task}

  @doc false
  def child_spec(args),
    do: %{id: __MODULE__, start: {__MODULE__, :start_link, [args]}, restart: :temporary, shutdown: 120_000}

  @doc false
  # Called in the supervisor's process: self() is the run's parent.
  def start_link(args), do: :proc_lib.start_link(__MODULE__, :init, [args, self()])

  @doc false
  # Numbers a tree with fresh ids, allocates its platform tasks (vehicles of
  # `inherit` may be reused: they belong to this run already) and removes the
  # `on` nodes, which only constrain the allocation.
  def prepare(task, ctx, run, inherit) do
    {tree, _} = Task.number(task, Dolphin.Engine.next_ids(Task.count(task)))

    case leaves(tree) do
      [] ->
        {:ok, strip(tree, %{})}

      leaves ->
        case Dolphin.Fleet.reserve(ctx.fleet, run, ctx.owner, leaves, inherit) do
          {:ok, assignment} ->
            allocation = Map.new(assignment, fn {id, v} -> {Integer.to_string(id), v} end)
            Dolphin.Events.emit(:allocated, %{run: run.id, allocation: allocation}, ctx.clock.now_ms())
            {:ok, strip(tree, assignment)}

          {:error, error} ->
            {:error, error}
        end
    end
  end

  @doc false
  # The platform tasks of a numbered tree, in order, with what constrains
  # them, as the fleet's allocation takes them (Dolphin.Fleet.Allocation.leaf):
  # the children of `|||` and `all_of` may run at the same time.
  @spec leaves(Task.t()) :: [Dolphin.Fleet.Allocation.leaf()]
  def leaves(tree), do: leaves(tree, [], nil)

  defp leaves(%PlatformTask{} = t, path, allowed),
    do: [%{id: t.id, name: Task.label(t), requirements: PlatformTask.requirements(t), allowed: allowed, path: Enum.reverse(path)}]

  defp leaves(%On{task: t, vehicles: set} = on, path, allowed) do
    ids = Dolphin.Fleet.VehicleSet.ids(set)
    allowed = if allowed, do: Enum.filter(allowed, &(&1 in ids)), else: ids
    leaves(t, [{on.id, :apart, 0} | path], allowed)
  end

  defp leaves(task, path, allowed) do
    how = if Task.kind(task) in [:concurrent, :all_of], do: :together, else: :apart

    task
    |> Task.children()
    |> Enum.with_index()
    |> Enum.flat_map(fn {child, i} -> leaves(child, [{task.id, how, i} | path], allowed) end)
  end

  defp strip(tree, assignment) do
    Task.postwalk(tree, fn
      %On{task: t} -> t
      %PlatformTask{id: id} = t -> %{t | vehicle: Map.get(assignment, id)}
      t -> t
    end)
  end

  @doc false
  # Waits (bounded, real ms) until the runs started by `caller` have ended.
  def await_runs_of(caller, bound), do: await(runs_of(caller), bound)

  @doc false
  # The runs `caller` started (not those started by their tasks' code).
  def runs_of(caller),
    do: for({pid, %{caller: ^caller}} <- Registry.select(Dolphin.Engine.Registry, [{{{:run, :_}, :"$1", :"$2"}, [], [{{:"$1", :"$2"}}]}]), do: pid)

  @doc false
  def await(pids, bound) do
    refs = Enum.map(pids, &Process.monitor/1)
    deadline = System.monotonic_time(:millisecond) + bound

    Enum.each(refs, fn ref ->
      receive do
        {:DOWN, ^ref, :process, _, _} -> :ok
      after
        max(deadline - System.monotonic_time(:millisecond), 0) -> Process.demonitor(ref, [:flush])
      end
    end)
  end

  @doc false
  def init({task, ctx, {caller, group_leader}, run_id}, sup) do
    # The run writes where its caller does (else its group leader would be
    # the application's); a dry run also knows its processes by it
    # (Dolphin.Check.Clock). Taken first, before anything could wait.
    Process.group_leader(self(), group_leader)
    Process.flag(:trap_exit, true)
    Context.put(ctx)
    Process.link(caller)
    # The `until`s' conditions are watched in one process of the run (Dolphin.Engine.Conditions).
    run = %{id: run_id, pid: self(), conditions: Conditions.start_link(ctx, run_id)}
    Registry.register(Dolphin.Engine.Registry, {:run, run_id}, %{caller: caller, owner: ctx.owner, task: task, instance: ctx.instance})
    :proc_lib.init_ack({:ok, self()})

    case prepare(task, ctx, run, []) do
      {:ok, tree} ->
        case Runner.start_node(tree, ctx, run, nil) do
          {:ok, root} -> loop(%{run: run, ctx: ctx, caller: caller, sup: sup, root: root, tree: tree, debug: :sys.debug_options([])})
          {:finished, result} -> done(%{run: run, ctx: ctx, caller: caller}, result)
          {:error, reason} -> done(%{run: run, ctx: ctx, caller: caller}, {:failed, Runner.failure(tree, reason)})
        end

      {:error, error} ->
        done(%{run: run, ctx: ctx, caller: caller}, {:error, error})
    end
  end

  # Every message is taken in arrival order (each has a clause below), so it
  # goes through the :sys debug hook first.
  defp loop(s) do
    receive do
      {:system, from, request} ->
        :sys.handle_system_msg(request, from, s.sup, __MODULE__, s.debug, s)

      msg ->
        s = if s.debug == [], do: s, else: %{s | debug: :sys.handle_debug(s.debug, &write_debug/3, s.run.id, {:in, msg})}
        handle_msg(msg, s)
    end
  end

  defp handle_msg(msg, %{root: root, caller: caller, sup: sup} = s) do
    case msg do
      {:"$dolphin_result", ^root, result} ->
        done(s, result)

      {:"$dolphin_run_stop", reason} ->
        done(s, stop_root(s, reason))

      {:EXIT, ^root, reason} ->
        done(s, {:failed, Runner.failure(s.tree, {:crashed, reason})})

      # Its conditions process crashed (an engine fault): nothing it watched
      # would end its task, so the run stops.
      {:EXIT, pid, reason} when pid == s.run.conditions ->
        stop_root(s, :shutdown)
        done(s, {:failed, Runner.failure(s.tree, {:crashed, {:conditions, reason}})})

      {:EXIT, ^caller, reason} ->
        stop_root(s, {:parent_exit, reason})
        release(s)
        exit(:normal)

      {:EXIT, ^sup, reason} ->
        stop_root(s, :shutdown)
        release(s)
        exit(reason)

      _other ->
        loop(s)
    end
  end

  # --- :sys callbacks ---

  @doc false
  def system_continue(_parent, debug, s), do: loop(%{s | debug: debug})

  @doc false
  # :sys.terminate/2: the tree stops first, as on any other way out.
  def system_terminate(reason, _parent, _debug, s) do
    stop_root(s, :shutdown)
    release(s)
    exit(reason)
  end

  use Dolphin.Engine.SysState

  @doc false
  def write_debug(device, {:in, msg}, run_id), do: IO.write(device, "*DBG* run #{run_id} got #{inspect(msg)}\n")

  defp stop_root(s, reason) do
    Runner.stop_node(s.root, reason)

    case Runner.collect(s.root, s.ctx) do
      {:ok, result} -> result
      {:error, why} -> {:failed, Runner.failure(s.tree, why)}
    end
  end

  defp done(s, result) do
    release(s)

    reply =
      case result do
        :done -> {:ok, :done}
        :stopped -> {:ok, :stopped}
        {:failed, failure} -> {:error, failure}
        {:error, error} -> {:error, error}
      end

    send(s.caller, {Dolphin.Engine, s.run.id, reply})
    exit(:normal)
  end

  defp release(s) do
    Dolphin.Engine.Stops.forget_run(s.run.id)
    Dolphin.Fleet.unreserve(s.ctx.fleet, s.run.id)
  catch
    # No fleet (a run without platform tasks in a bare test): nothing was reserved.
    :exit, _ -> :ok
  end
end
