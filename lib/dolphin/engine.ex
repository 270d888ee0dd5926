defmodule Dolphin.Engine do
  @moduledoc """
  The Dolphin engine: tasks as data, run as process trees.

  Tasks are values (`Dolphin.Engine.Task`) built by the functions below — the
  script macros of `Dolphin.Script` expand to them — and nothing moves until
  they run. `run/2` (and a script's `execute`) allocates vehicles to the
  platform tasks of a task, then runs it: one process per node of the tree.

      import Dolphin.Engine
      survey = Dolphin.Engine.FakePlatform.task("survey", duration: :infinity)
      t = sequence([until(survey, fn snap -> Dolphin.Engine.Snapshot.battery(snap, v) < 0.3 end), idle(5_000)])
      {:ok, :done} = Dolphin.Engine.run(t)

  ## Results

  A task ends `:done`, `:stopped` (stopped from outside: by its parent or the
  operator) or `{:failed, %Dolphin.Engine.Failure{}}` — naming the task where
  the failure began, its vehicle and the reason. `run/2` returns
  `{:ok, :done | :stopped}` or `{:error, failure}` (or
  `{:error, %Dolphin.Fleet.AllocationError{}}` when no vehicles fit).
  Combinators' semantics are in their modules (`Dolphin.Engine.Until`, ...).
  A child stopped from outside (by the operator) counts as completed for
  its parent.

  ## Processes and exit semantics

  A run is a `Dolphin.Engine.Run` process under `Dolphin.Engine.Runs`,
  **linked** to the caller (the script): if the caller dies, the run stops its
  tree before exiting. The run is the parent of the root node; every node is a
  process **linked** to its parent, and every node **traps exits**:

    * a node's child is linked to it (shared fate) and reports its result with
      a message before exiting normally; a child that dies without reporting
      (a crash) is a failure of that child;
    * when a node's parent dies (an exit signal, also `:kill`), the node stops
      its own subtree as below and exits — so killing any node, run or script
      still stops every platform task under it;
    * user code (`action`, `watch` handlers) runs in a helper process linked
      to its node and is killed when the node stops (runs it started with
      `execute` stop with it, and the node waits for them);
    * a platform task's process is linked to its leaf; the leaf calls the
      platform's `stop/2` and waits for it (bounded by `stop_timeout_ms`,
      15 s of clock time; then it is killed and the task fails) — for a
      mission, the vehicle holds position.

  Runs and nodes are `:proc_lib` processes with full `:sys` support: each
  answers system messages in every phase of its life (running, or stopped
  and waiting for its report), so `:sys.get_state/1`, `:sys.trace/2`,
  `:sys.install/2` and observer look into any process of a running tree. A
  run's `:sys` parent is its supervisor, handed to it when it starts (an exit
  from it stops the tree, then the run exits with the same reason); a node's
  is its parent node (or run). `:sys.terminate/2` on a node or a run stops
  its subtree first, like any other way out.

  Stopping a subtree (`until`, `during`, `one_of`, a failed sibling in `|||`
  or `all_of`, the operator, the end of `--for`) is a two-phase protocol:
  **stop** travels down the whole subtree at once (every platform stop runs
  in parallel: vehicles hold without waiting for each other), then the
  parent asks each child for its **report**, in start order, and each node
  reports after its own children. No node is gone before everything under it
  is stopped. A stop that fails (a vehicle that would not hold) makes the
  result a failure rather than `:stopped`.

  ## Order of events

  Events (`Dolphin.Events`: `task_started`, `task_finished`,
  `condition_met`, ...) follow the tree deterministically: a node's
  `task_started` precedes its children's; a node's initial subtree has fully
  started before its next sibling starts (a handshake; a child that ends as
  it starts hands its result back with the handshake and its parent deals
  with it at once); a node's `task_finished` follows all of its children's;
  stopped children finish in start order; user code starts on the next clock
  tick; timers due at the same time fire in the order they were set. With a deterministic
  time source (`:clock` option) the whole event sequence is reproducible —
  the property tests compare it with a reference interpreter.

  ## Conditions

  Conditions are functions of a snapshot (`Dolphin.Engine.Cond`,
  `Dolphin.Engine.Snapshot`) evaluated when their node starts and again on
  every change of what they read — a vehicle's view (`Dolphin.Vehicles.View`,
  published whole by the vehicle's owner), a signal — plus a slow tick
  (`tick_ms`, 1 s of clock time) for conditions on anything else. Each
  node's `Dolphin.Engine.Watcher` follows the vehicles and signals its
  conditions read and hands each condition its snapshot as its argument; a
  change re-evaluates only the conditions that read it. A frame thus
  travels link -> vehicle process -> view published -> node, crossing each
  layer once. Reaction is thus event-driven: see
  `bench/reaction.exs` for the latency from a state change to the stop of
  the task it ends.

  ## Allocation

  See `Dolphin.Fleet.Allocation`: platform tasks get vehicles among those
  the script picked and that no other run holds; tasks that may run at the
  same time get distinct vehicles, sequential ones may share, `on/2`
  restricts, requirements are honoured; a real search, with an error naming
  the task that cannot be served.
  """

  alias Dolphin.Engine.{Action, AllOf, Concurrent, Cond, Condition, Context, During, Idle, On, OneOf, OnSensor, PlatformTask, Run, Sequence, Task, Until, WaitFor, Watch}

  @type task :: Task.t()
  @type result :: {:ok, :done | :stopped} | {:error, Dolphin.Engine.Failure.t() | Dolphin.Fleet.AllocationError.t()}

  # --- building tasks ---

  @doc "A task that completes after `duration` ms of clock time."
  @spec idle(non_neg_integer(), keyword()) :: Idle.t()
  def idle(duration, opts \\ [])
  def idle(d, opts) when is_integer(d) and d >= 0, do: build(%Idle{duration: d}, opts)
  def idle(d, opts) when is_float(d) and d >= 0, do: idle(round(d), opts)
  def idle(d, _opts), do: raise(ArgumentError, "idle takes a duration in milliseconds, got: #{inspect(d)}")

  @doc "A task that runs `fun` (no arguments) once; an exception fails it."
  @spec action((() -> term()), keyword()) :: Action.t()
  def action(fun, opts \\ [])
  def action(fun, opts) when is_function(fun, 0), do: build(%Action{fun: fun}, opts)
  def action(fun, _opts), do: raise(ArgumentError, "action takes a function of no arguments, got: #{inspect(fun)}")

  @doc "A task that completes when the condition (a `Cond` or a 0-arity function) holds."
  @spec condition(Cond.t() | (() -> term()), keyword()) :: Condition.t()
  def condition(c, opts \\ []), do: build(%Condition{cond: Cond.from(c)}, opts)

  @doc "Tasks one after the other (`t1 >>> t2`)."
  @spec sequence([term()], keyword()) :: Sequence.t()
  def sequence(tasks, opts \\ []) when is_list(tasks), do: build(%Sequence{tasks: flatten(Sequence, tasks)}, opts)

  @doc "Tasks at the same time (`t1 ||| t2`)."
  @spec concurrent([term()], keyword()) :: Concurrent.t()
  def concurrent(tasks, opts \\ []) when is_list(tasks), do: build(%Concurrent{tasks: flatten(Concurrent, tasks)}, opts)

  @doc "`t` whose platform tasks may only use vehicles of `set` (a vehicle set or ids)."
  @spec on(term(), Dolphin.Fleet.VehicleSet.t() | [non_neg_integer()], keyword()) :: On.t()
  def on(task, set, opts \\ []), do: build(%On{task: Task.new!(task), vehicles: Dolphin.Fleet.VehicleSet.new(set)}, opts)

  @doc "`t` until the condition holds."
  @spec until(term(), Cond.t() | (() -> term()), keyword()) :: Until.t()
  def until(task, c, opts \\ []), do: build(%Until{task: Task.new!(task), cond: Cond.from(c)}, opts)

  @doc "`t` for at most `duration` ms of clock time."
  @spec during(non_neg_integer(), term(), keyword()) :: During.t()
  def during(duration, task, opts \\ [])
  def during(d, task, opts) when is_integer(d) and d >= 0, do: build(%During{duration: d, task: Task.new!(task)}, opts)
  def during(d, task, opts) when is_float(d) and d >= 0, do: during(round(d), task, opts)
  def during(d, _task, _opts), do: raise(ArgumentError, "during takes a duration in milliseconds, got: #{inspect(d)}")

  @doc "Waits for the condition, then runs `then` (if given)."
  @spec wait_for(Cond.t() | (() -> term()), term() | nil, keyword()) :: WaitFor.t()
  def wait_for(c, then \\ nil, opts \\ []), do: build(%WaitFor{cond: Cond.from(c), then: then && Task.new!(then)}, opts)

  @doc "The first branch (`{condition, task}`) whose condition holds runs."
  @spec one_of([{Cond.t() | (() -> term()), term()}], keyword()) :: OneOf.t()
  def one_of(branches, opts \\ []), do: build(%OneOf{branches: branches!(branches, :one_of)}, opts)

  @doc "Every branch (`{condition, task}`) runs its task once its condition holds."
  @spec all_of([{Cond.t() | (() -> term()), term()}], keyword()) :: AllOf.t()
  def all_of(branches, opts \\ []), do: build(%AllOf{branches: branches!(branches, :all_of)}, opts)

  @doc """
  `t`, whose failure is handled by `on_error:` (`:ignore`, `:propagate`,
  `:reassign` or a function of the failure); with `:reassign`, `from:` (a
  vehicle set or ids) limits the vehicles that may take a task over. See
  `Dolphin.Engine.Watch`.
  """
  @spec watch(term(), keyword()) :: Watch.t()
  def watch(task, opts \\ []) do
    {on_error, opts} = Keyword.pop(opts, :on_error, :propagate)
    {from, opts} = Keyword.pop(opts, :from)

    unless on_error in [:ignore, :propagate, :reassign] or is_function(on_error, 1),
      do: raise(ArgumentError, "on_error must be :ignore, :propagate, :reassign or a function of one argument, got: #{inspect(on_error)}")

    if from != nil and on_error != :reassign,
      do: raise(ArgumentError, "watch: from: goes with on_error: :reassign, got on_error: #{inspect(on_error)}")

    build(%Watch{task: Task.new!(task), on_error: on_error, from: from && Dolphin.Fleet.VehicleSet.new(from)}, opts)
  end

  @doc """
  `watch(t, on_error: :reassign, from: set)`: a mission of `t` whose vehicle
  is lost (or fails it: a failsafe, a refused arm) is resumed by another
  vehicle of `set` (default: any the script picked). See `Dolphin.Engine.Watch`.
  """
  @spec reassign(term(), keyword()) :: Watch.t()
  def reassign(task, opts \\ []) do
    unless Keyword.keyword?(opts) and Keyword.keys(opts) -- [:from, :name, :meta] == [],
      do: raise(ArgumentError, "reassign takes from: (a vehicle set or ids), got: #{inspect(opts)}")

    watch(task, [on_error: :reassign] ++ opts)
  end

  @doc """
  Missions flown while a sensor is watched: `missions` maps each vehicle
  (a one-vehicle set or an id) to its `Dolphin.Mission`; a reading of
  `sensor` (a `Dolphin.Sensors.Sensor`) above `above:` at a new place
  (farther than `apart:` metres, default 100, from the detections made)
  sends the nearest vehicle free to fly `then:`'s task for it, its mission
  resumed afterwards (`finally:`, a task for a vehicle with nothing left of
  its mission after a look). See `Dolphin.Engine.OnSensor`.
  """
  @spec on_sensor(map() | [{term(), term()}], Dolphin.Sensors.Sensor.t(), keyword()) :: OnSensor.t()
  def on_sensor(missions, %Dolphin.Sensors.Sensor{} = sensor, opts) do
    {above, opts} = Keyword.pop(opts, :above)
    {apart, opts} = Keyword.pop(opts, :apart, 100)
    {then, opts} = Keyword.pop(opts, :then)
    {finally, opts} = Keyword.pop(opts, :finally)

    unless is_number(above), do: raise(ArgumentError, "on_sensor takes above: (the threshold, a number), got: #{inspect(above)}")
    unless is_number(apart) and apart >= 0, do: raise(ArgumentError, "on_sensor takes apart: (metres, 0 or more), got: #{inspect(apart)}")
    unless is_function(then, 1), do: raise(ArgumentError, "on_sensor takes then: (a function of the detection, giving a task), got: #{inspect(then)}")

    missions =
      for {v, m} <- Enum.to_list(missions) do
        case {Dolphin.Fleet.VehicleSet.ids(Dolphin.Fleet.VehicleSet.new(v)), m} do
          {[id], %Dolphin.Mission{} = mission} -> {id, mission}
          {[_], other} -> raise ArgumentError, "on_sensor flies a mission on each vehicle (mission \"name\" do ... end), got: #{inspect(other)}"
          {ids, _} -> raise ArgumentError, "on_sensor gives each mission one vehicle, got: #{inspect(ids)}"
        end
      end

    if missions == [], do: raise(ArgumentError, "on_sensor takes at least one vehicle and its mission")
    build(%OnSensor{missions: missions, sensor: sensor, above: above, apart: apart * 1.0, then: then, finally: finally && Task.new!(finally)}, opts)
  end

  @doc "A task of a platform (see `Dolphin.Engine.Platform`); `spec` is the platform's description of it."
  @spec platform_task(module(), term(), keyword()) :: PlatformTask.t()
  def platform_task(platform, spec, opts \\ []) when is_atom(platform) do
    Code.ensure_loaded(platform)

    unless function_exported?(platform, :start, 3) and function_exported?(platform, :stop, 2),
      do: raise(ArgumentError, "#{inspect(platform)} does not implement Dolphin.Engine.Platform")

    build(%PlatformTask{platform: platform, spec: spec}, opts)
  end

  @doc "The task with a name (shown in events, errors and the console)."
  @spec named(term(), String.t()) :: task()
  def named(task, name) when is_binary(name), do: %{Task.new!(task) | name: name}

  defp build(task, opts) do
    opts = Keyword.new(opts)
    %{task | name: Keyword.get(opts, :name, task.name), meta: Map.new(Keyword.get(opts, :meta, task.meta))}
  end

  defp flatten(kind, tasks) do
    Enum.flat_map(tasks, fn t ->
      case Task.new!(t) do
        %{__struct__: ^kind, name: nil, tasks: inner} -> inner
        t -> [t]
      end
    end)
  end

  defp branches!([_ | _] = branches, _what), do: Enum.map(branches, fn {c, t} -> {Cond.from(c), Task.new!(t)} end)
  defp branches!(other, what), do: raise(ArgumentError, "#{what} takes a non-empty list of {condition, task}, got: #{inspect(other)}")

  # --- running ---

  @doc """
  Runs a task and waits for its end. Options (over the caller's
  `Dolphin.Engine.Context`): `:fleet`, `:clock` (a `Dolphin.Engine.TimeSource`),
  `:owner` (whose picked vehicles may be used; default the caller),
  `:tick_ms`, `:stop_timeout_ms`.
  """
  @spec run(term(), keyword()) :: result()
  def run(task, opts \\ []) do
    {:ok, run_id} = start(task, opts)
    await(run_id)
  end

  @doc "Starts a run (linked to the caller); its result comes to `await/2`."
  @spec start(term(), keyword()) :: {:ok, integer()}
  def start(task, opts \\ []) do
    task = Task.new!(task)
    ctx = Context.new(opts)
    run_id = next_ids(1)
    {:ok, _pid} = DynamicSupervisor.start_child(Dolphin.Engine.Runs, {Run, {task, ctx, {self(), Process.group_leader()}, run_id}})
    {:ok, run_id}
  end

  @doc "Waits for the result of a run started by the caller."
  @spec await(integer(), timeout()) :: result() | {:error, :timeout}
  def await(run_id, timeout \\ :infinity) do
    receive do
      {Dolphin.Engine, ^run_id, result} -> result
    after
      timeout -> {:error, :timeout}
    end
  end

  @doc """
  Runs a task; returns `:ok` when it is done (or `:stopped` if the operator
  stopped it), raises `Dolphin.Engine.TaskError` when it fails and
  `Dolphin.Fleet.AllocationError` when no vehicles fit.
  """
  @spec execute!(term(), keyword()) :: :ok | :stopped
  def execute!(task, opts \\ []) do
    case run(task, opts) do
      {:ok, :done} -> :ok
      {:ok, :stopped} -> :stopped
      {:error, %Dolphin.Engine.Failure{} = f} -> raise Dolphin.Engine.TaskError, failure: f
      {:error, %Dolphin.Fleet.AllocationError{} = e} -> raise e
    end
  end

  @doc "Stops a run (its tree stops as described above); the caller of the run gets `{:ok, :stopped}`."
  @spec stop(integer(), term()) :: :ok | {:error, :not_found}
  def stop(run_id, reason \\ :operator) do
    case Registry.lookup(Dolphin.Engine.Registry, {:run, run_id}) do
      [{pid, _}] -> send(pid, {:"$dolphin_run_stop", reason}) && :ok
      [] -> {:error, :not_found}
    end
  end

  @doc "Stops one running task (and its subtree); its parent goes on as if it had completed."
  @spec stop_task(integer(), term()) :: :ok | {:error, :not_found}
  def stop_task(task_id, reason \\ :operator) do
    case Registry.lookup(Dolphin.Engine.Registry, {:task, task_id}) do
      [{pid, _}] -> send(pid, {:"$dolphin_operator_stop", reason}) && :ok
      [] -> {:error, :not_found}
    end
  end

  @doc "The running runs of the calling process's `Dolphin.Instance`: `%{run, pid, owner, task}`."
  @spec runs() :: [map()]
  def runs do
    registered(:run)
    |> Enum.map(fn {id, pid, meta} -> %{run: id, pid: pid, owner: meta.owner, task: meta.task} end)
    |> Enum.sort_by(& &1.run)
  end

  @doc """
  The running tasks of the calling process's `Dolphin.Instance` (whose
  vehicles they fly), by id: `%{task_id, run, parent_id, kind, name,
  vehicle, pid}` (for a console's tree view).
  """
  @spec tasks() :: [map()]
  def tasks do
    registered(:task)
    |> Enum.map(fn {id, pid, meta} -> meta |> Map.delete(:instance) |> Map.merge(%{task_id: id, pid: pid}) end)
    |> Enum.sort_by(& &1.task_id)
  end

  # The runs (or tasks) registered by the calling process's instance: {id, pid, meta}.
  defp registered(kind) do
    instance = Dolphin.Instance.current()
    Registry.select(Dolphin.Engine.Registry, [{{{kind, :"$1"}, :"$2", :"$3"}, [], [{{:"$1", :"$2", :"$3"}}]}]) |> Enum.filter(fn {_, _, meta} -> meta.instance == instance end)
  end

  @doc false
  # A block of `n` fresh ids (tasks and runs share them); returns the first.
  def next_ids(n) do
    ref = :persistent_term.get({Dolphin.Engine, :ids})
    :atomics.add_get(ref, 1, n) - n + 1
  end
end
