defmodule Dolphin.Engine.Runner do
  @moduledoc false
  # The process shell of a task node: one process per combinator node, running
  # the node's pure semantics (Dolphin.Engine.Node) and doing their effects.
  # Exit semantics and the start/stop protocol are documented in Dolphin.Engine.
  # A proc_lib process with full :sys support (system messages, debug/trace
  # hooks), whose :sys parent is its parent node or run. One cohesive thing
  # past 500 lines: the receive loop, the effects, the two-phase stop and the
  # :sys callbacks all work on the one node state that :sys hands back.
  #
  # Messages (parent -> child): {:"$dolphin_stop", reason} (phase 1: stop what
  # runs under you), {:"$dolphin_report", parent} (phase 2: finish and report),
  # {:"$dolphin_operator_stop", reason} (stop and report at once).
  # Child -> parent: {:"$dolphin_started", pid, nil} once its initial subtree
  # runs (or {:"$dolphin_started", pid, {:finished, result}} if it ended at once),
  # {:"$dolphin_result", pid, result} as it ends.

  alias Dolphin.Engine.{Conditions, Context, Failure, PlatformTask, Stops, Task, Watcher}

  # A node's state, which :sys.get_state/1 hands back.
  defstruct [
    :task,
    :id,
    :mod,
    :kind,
    :name,
    :vehicle,
    :parent,
    :parent_id,
    :ctx,
    :run,
    :cstate,
    :watcher,
    :platform,
    :tick,
    :debug,
    :stop_alias,
    :stop_outcome,
    children: %{},
    pids: %{},
    started: 0,
    watches: [],
    elsewhere: %{},
    timers: %{},
    code: %{},
    acked: false,
    halted: :ok
  ]

  @typedoc """
  A node's state: its task and where it stands (`parent`, `parent_id`,
  `run`, `ctx`); `cstate`, its combinator's own state (`Dolphin.Engine.Node`);
  `children`, key => %{pid, task, n} (n: how many children this node had
  started before it, which orders them), `pids`, pid => key of each child,
  and `started`, how many children it has started;
  `watches`, [{key, cond}] in watch order, and `watcher`, what those
  conditions read (and the vehicle of a platform task); `elsewhere`, key =>
  cond of the conditions the run's conditions process watches for this
  node (an `until`'s: `Dolphin.Engine.Conditions`); `timers`, key =>
  {ref, token, at} (at: its deadline in clock ms); `code`, key => {:pending, ref, token, fun} | {:running, pid};
  `platform`, the platform task's process (a leaf), `stop_alias`, where its
  answer to a stop comes (`Dolphin.Engine.Stops`), and `stop_outcome`, that
  answer when it came before the leaf was told to stop; `tick`, the 1 s timer of
  conditions on time; `acked`, whether the parent was told it started;
  `halted`, the outcome of the platform's stop in phase 1; `debug`, the :sys
  debug options (`:sys.trace/2`, `:sys.log/2`, ...).
  """
  @type t :: %__MODULE__{
          task: Task.t(),
          id: non_neg_integer(),
          mod: module(),
          kind: atom(),
          name: String.t() | nil,
          vehicle: term(),
          parent: pid(),
          parent_id: non_neg_integer() | nil,
          ctx: Context.t(),
          run: map(),
          cstate: term(),
          watcher: Watcher.t(),
          platform: pid() | nil,
          tick: reference() | nil,
          debug: [:sys.dbg_opt()],
          children: %{term() => %{pid: pid(), task: Task.t(), n: non_neg_integer()}},
          pids: %{pid() => term()},
          started: non_neg_integer(),
          watches: [{term(), Dolphin.Engine.Cond.t()}],
          elsewhere: %{term() => Dolphin.Engine.Cond.t()},
          stop_alias: reference() | nil,
          stop_outcome: :ok | {:error, term()} | nil,
          timers: %{term() => {reference(), reference(), integer()}},
          code: %{term() => {:pending, reference(), reference(), function()} | {:running, pid()}},
          acked: boolean(),
          halted: term()
        }

  # Real time a parent waits for a child's initial subtree to start.
  @start_timeout 30_000

  # --- used by parents (nodes and Dolphin.Engine.Run) ---

  @doc false
  # Starts a node (linked to the caller) and waits until its initial subtree
  # has started: {:ok, pid}, or {:finished, result} if it ended at once (its
  # result comes with the acknowledgement, so that the parent handles it before
  # anything else: the order of events stays deterministic), or {:error, reason}.
  def start_node(task, ctx, run, parent_id) do
    # One argument: proc_lib makes a dummy argument list of the initial
    # call's arity on every exit, a cost a burst of ending nodes feels.
    pid = :proc_lib.spawn_link(__MODULE__, :init_node, [{task, self(), ctx, run, parent_id}])

    receive do
      {:"$dolphin_started", ^pid, nil} ->
        {:ok, pid}

      {:"$dolphin_started", ^pid, {:finished, result}} ->
        {:finished, result}

      {:EXIT, ^pid, reason} ->
        {:error, {:crashed, reason}}
    after
      @start_timeout ->
        Process.exit(pid, :kill)
        receive do: ({:EXIT, ^pid, _} -> :ok)
        {:error, {:crashed, :start_timeout}}
    end
  end

  @doc false
  def stop_node(pid, reason), do: send(pid, {:"$dolphin_stop", reason})

  @doc false
  # Phase 2: asks a (stopped) node for its result and waits, bounded; returns
  # {:ok, result} | {:error, raw_reason} (crashed or timed out and killed).
  def collect(pid, ctx) do
    send(pid, {:"$dolphin_report", self()})
    # Its subtree stops in parallel with this wait, each platform stop bounded
    # by stop_timeout_ms: wait for longer than that.
    bound = 2 * ctx.clock.real_ms(ctx.stop_timeout_ms) + 1_000

    receive do
      {:"$dolphin_result", ^pid, result} ->
        {:ok, result}

      {:EXIT, ^pid, reason} ->
        {:error, {:crashed, reason}}
    after
      bound ->
        Process.exit(pid, :kill)
        receive do: ({:EXIT, ^pid, _} -> :ok)
        {:error, {:crashed, :no_report_after_stop}}
    end
  end

  @doc false
  def failure(task, reason) do
    %Failure{
      task_id: task.id,
      kind: Task.kind(task),
      name: Task.label(task),
      vehicle: vehicle_of(task),
      meta: task.meta,
      reason: reason
    }
  end

  defp vehicle_of(%PlatformTask{vehicle: v}), do: v
  defp vehicle_of(_task), do: nil

  # --- the node process ---

  @doc false
  # A node ends by throwing :"$dolphin_node_end" (end_node/0) from wherever
  # it finished, and returns from here: exit(:normal) would go through
  # proc_lib's exit path, which builds a crash report's dummy arguments and
  # formats its reason for every node, a cost a burst of ending nodes feels.
  def init_node(arg) do
    run_node(arg)
  catch
    :throw, :"$dolphin_node_end" -> :ok
  end

  defp end_node, do: throw(:"$dolphin_node_end")

  defp run_node({task, parent, ctx, run, parent_id}) do
    Process.flag(:trap_exit, true)
    Context.put(ctx)

    s = %__MODULE__{
      task: task,
      id: task.id,
      mod: task.__struct__,
      kind: Task.kind(task),
      name: Task.label(task),
      vehicle: vehicle_of(task),
      parent: parent,
      parent_id: parent_id,
      ctx: ctx,
      run: run,
      watcher: Watcher.new(Context.source(ctx), ctx.signals),
      debug: :sys.debug_options([])
    }

    Registry.register(Dolphin.Engine.Registry, {:task, s.id}, %{run: run.id, parent_id: parent_id, kind: s.kind, name: s.name, vehicle: s.vehicle, instance: ctx.instance})
    emit(s, :task_started, %{parent_id: parent_id, kind: s.kind, name: s.name, vehicle: s.vehicle})

    {effects, cstate} = s.mod.init(task)
    s = run_effects(effects, %{s | cstate: cstate})
    loop(ack(s))
  end

  defp ack(%{acked: true} = s), do: s

  defp ack(s) do
    send(s.parent, {:"$dolphin_started", self(), nil})
    %{s | acked: true}
  end

  # Every message is taken in arrival order (each has a clause below), so it
  # goes through the :sys debug hook first.
  defp loop(s) do
    receive do
      {:system, from, request} ->
        :sys.handle_system_msg(request, from, s.parent, __MODULE__, s.debug, {:running, s})

      msg ->
        handle_msg(msg, debug_in(s, msg))
    end
  end

  defp handle_msg(msg, s) do
    parent = s.parent
    platform = s.platform
    stop_alias = s.stop_alias

    case msg do
      {:"$dolphin_result", pid, result} ->
        case child_key(s, pid) do
          nil -> loop(s)
          key -> s |> drop_child(key) |> feed({:finished, key, result}) |> loop()
        end

      {:"$dolphin_timer", key, token} ->
        case s.timers do
          %{^key => {_ref, ^token, at}} -> s |> timer_fired(key, token, at) |> loop()
          _ -> loop(s)
        end

      {:"$dolphin_code_start", key, token} ->
        case s.code do
          %{^key => {:pending, _ref, ^token, fun}} -> loop(%{s | code: Map.put(s.code, key, {:running, spawn_code(s, key, fun)})})
          _ -> loop(s)
        end

      {:"$dolphin_code", key, pid, result} ->
        case s.code do
          %{^key => {:running, ^pid}} -> %{s | code: Map.delete(s.code, key)} |> feed({:code_result, key, result}) |> loop()
          _ -> loop(s)
        end

      {:"$dolphin_tick", token} ->
        case s.tick do
          {_ref, ^token} -> %{s | tick: nil} |> reevaluate(:all) |> ensure_tick() |> loop()
          _ -> loop(s)
        end

      {:dolphin, {:vehicle, id}, {:view, view}} ->
        s = %{s | watcher: Watcher.update(s.watcher, view)}

        s =
          if s.platform != nil and s.vehicle == id and not view.connected?,
            do: feed(s, {:vehicle_lost, id}),
            else: s

        loop(reevaluate(s, {:vehicle, id}))

      {:dolphin, {:dolphin_signals, table}, _} ->
        loop(reevaluate(s, {:signals, table}))

      # The run's conditions process found this node's condition true and
      # sent the stops of the platforms under it; the node says
      # condition_met and stops its subtree as if it had found it itself
      # (unless it no longer watches it: it has ended meanwhile).
      {:"$dolphin_condition", key} ->
        case Map.pop(s.elsewhere, key) do
          {nil, _} -> loop(s)
          {_cond, elsewhere} -> %{s | elsewhere: elsewhere} |> feed({:condition, key}) |> loop()
        end

      # ... or could not evaluate it: watched here again (and evaluated at once).
      {:"$dolphin_condition_back", key} ->
        case Map.pop(s.elsewhere, key) do
          {nil, _} -> loop(s)
          {cond, elsewhere} -> %{s | elsewhere: elsewhere, watches: s.watches ++ [{key, cond}]} |> ensure_tick() |> reevaluate({:key, key}) |> loop()
        end

      {:dolphin_platform, ^platform, msg} when platform != nil ->
        # Once it reported its end, the platform's process is going: nothing to stop.
        s = if msg == :done or match?({:failed, _}, msg), do: platform_ended(s), else: s
        loop(feed(s, {:platform, msg}))

      # The platform's answer to a stop another process sent it
      # (Dolphin.Engine.Stops), before this leaf was told to stop: kept for then.
      {[:alias | ^stop_alias], reply} when platform != nil ->
        loop(%{platform_ended(s) | stop_outcome: stop_outcome(reply)})

      {:"$dolphin_stop", reason} ->
        s |> halt(reason) |> stopped(reason)

      {:"$dolphin_report", _} ->
        s |> halt(:stopped) |> finish_stopped(:stopped, true)

      {:"$dolphin_operator_stop", reason} ->
        s |> halt(reason) |> finish_stopped(reason, true)

      {:EXIT, ^parent, reason} ->
        s |> halt({:parent_exit, reason}) |> finish_stopped({:parent_exit, reason}, false)

      {:EXIT, pid, reason} ->
        loop(exited(s, pid, reason))

      _other ->
        loop(s)
    end
  end

  # Phase 1 done: waits for the parent to ask for the report (phase 2), or to die.
  defp stopped(s, reason) do
    parent = s.parent

    receive do
      {:system, from, request} ->
        :sys.handle_system_msg(request, from, parent, __MODULE__, s.debug, {{:stopped, reason}, s})

      {:"$dolphin_report", _} = msg ->
        s |> debug_in(msg) |> finish_stopped(reason, true)

      {:EXIT, ^parent, why} = msg ->
        s |> debug_in(msg) |> finish_stopped({:parent_exit, why}, false)
    end
  end

  # --- :sys callbacks ---

  @doc false
  def system_continue(_parent, debug, {:running, s}), do: loop(%{s | debug: debug})
  def system_continue(_parent, debug, {{:stopped, reason}, s}), do: stopped(%{s | debug: debug}, reason)

  @doc false
  # :sys.terminate/2: the subtree stops first, as on any other way out.
  def system_terminate(reason, _parent, _debug, {_phase, s}) do
    halt(s, :shutdown)
    Enum.each(in_start_order(s), &collected(s, &1))
    exit(reason)
  end

  @doc false
  def system_get_state({_phase, s}), do: {:ok, s}

  @doc false
  def system_replace_state(fun, {phase, s}) do
    s = fun.(s)
    {:ok, s, {phase, s}}
  end

  @doc false
  def system_code_change(misc, _module, _old_vsn, _extra), do: {:ok, misc}

  defp debug_in(%{debug: []} = s, _msg), do: s
  defp debug_in(s, msg), do: %{s | debug: :sys.handle_debug(s.debug, &write_debug/3, {s.kind, s.id}, {:in, msg})}

  @doc false
  def write_debug(device, {:in, msg}, {kind, id}), do: IO.write(device, "*DBG* task #{id} (#{kind}) got #{inspect(msg)}\n")

  defp exited(s, pid, reason) do
    cond do
      key = child_key(s, pid) ->
        # A child that died without reporting: an engine crash, a failure of that task.
        child = s.children[key]
        s |> drop_child(key) |> feed({:finished, key, {:failed, failure(child.task, {:crashed, reason})}})

      key = Enum.find_value(s.code, fn {k, v} -> if v == {:running, pid}, do: k end) ->
        %{s | code: Map.delete(s.code, key)} |> feed({:code_result, key, {:error, {:exit, reason}}})

      # Sent a stop by another process, it ended before it answered: it had
      # finished or failed, and counts as stopped (as when the leaf asks).
      pid == s.platform and s.stop_alias != nil and Stops.sent?(s.id) ->
        %{platform_ended(s) | stop_outcome: :ok}

      pid == s.platform ->
        s |> platform_ended() |> feed({:platform_exit, reason})

      true ->
        s
    end
  end

  # A concurrent node of a thousand children looks them up by pid and drops
  # them as each ends: by map, not by walking a list (which made a burst of
  # endings quadratic).
  defp child_key(s, pid), do: Map.get(s.pids, pid)

  defp drop_child(s, key) do
    {%{pid: pid}, children} = Map.pop(s.children, key)
    %{s | children: children, pids: Map.delete(s.pids, pid)}
  end

  # The children still running, in the order they were started.
  defp in_start_order(s), do: s.children |> Map.values() |> Enum.sort_by(& &1.n)

  # --- effects ---

  defp feed(s, event) do
    {effects, cstate} = s.mod.handle(event, s.cstate)
    run_effects(effects, %{s | cstate: cstate})
  end

  defp run_effects(effects, s), do: Enum.reduce(effects, s, &effect/2)

  defp effect({:start, key, task}, s) do
    case start_node(task, s.ctx, s.run, s.id) do
      {:ok, pid} -> %{s | children: Map.put(s.children, key, %{pid: pid, task: task, n: s.started}), pids: Map.put(s.pids, pid, key), started: s.started + 1}
      {:finished, result} -> feed(s, {:finished, key, result})
      {:error, reason} -> feed(s, {:finished, key, {:failed, failure(task, reason)}})
    end
  end

  defp effect({:start_new, key, value}, s), do: effect({:start_new, key, value, []}, s)

  # `also`: vehicles this run holds that the new task may use besides the
  # node's own (a `reassign` hands a task over to one of them).
  defp effect({:start_new, key, value, also}, s) do
    task = Task.new!(value)

    case Dolphin.Engine.Run.prepare(task, s.ctx, s.run, Enum.uniq(vehicles_in(s.task) ++ also)) do
      {:ok, task} -> effect({:start, key, task}, s)
      {:error, reason} -> feed(s, {:finished, key, {:failed, failure(task, reason)}})
    end
  end

  defp effect({:stop, keys, reason}, s) do
    running = Enum.filter(keys, &Map.has_key?(s.children, &1))
    Enum.each(running, &stop_node(s.children[&1].pid, reason))

    Enum.reduce(running, s, fn key, s ->
      case Map.fetch(s.children, key) do
        {:ok, child} -> s |> drop_child(key) |> feed({:finished, key, collected(s, child)})
        :error -> s
      end
    end)
  end

  defp effect({:check, key, cond}, s) do
    {result, watcher} = Watcher.evaluate(s.watcher, key, cond)
    s = %{s | watcher: watcher}

    case result do
      {:ok, holds} ->
        s = feed(s, {:checked, key, holds})
        # What it read stays followed only if the node goes on watching it.
        if List.keymember?(s.watches, key, 0), do: s, else: %{s | watcher: Watcher.forget(s.watcher, key)}

      {:error, e, _} ->
        finish(s, {:failed, {:condition_error, cond.source, e}})
    end
  end

  # An `until`'s condition is watched by the run's conditions process, which
  # stops the platforms under it itself (Dolphin.Engine.Conditions); one
  # that follows the vehicles its task flies is watched here.
  defp effect({:watch, key, %{follow: false} = cond}, %{kind: :until, run: %{conditions: hub}} = s) do
    Conditions.watch(hub, key, cond, s.id, last_id(s.task))
    %{s | elsewhere: Map.put(s.elsewhere, key, cond), watcher: Watcher.forget(s.watcher, key)}
  end

  defp effect({:watch, key, cond}, s), do: ensure_tick(%{follow_flown(s, cond) | watches: s.watches ++ [{key, cond}]})

  defp effect({:unwatch, key}, %{elsewhere: elsewhere} = s) when is_map_key(elsewhere, key) do
    Conditions.unwatch(s.run.conditions, key)
    %{s | elsewhere: Map.delete(elsewhere, key)}
  end

  defp effect({:unwatch, key}, s), do: %{s | watches: List.keydelete(s.watches, key, 0), watcher: Watcher.forget(s.watcher, key)}

  defp effect({:timer, key, ms}, s) do
    token = make_ref()
    ref = s.ctx.clock.send_after(self(), {:"$dolphin_timer", key, token}, ms)
    %{s | timers: Map.put(s.timers, key, {ref, token, s.ctx.clock.now_ms() + ms})}
  end

  defp effect({:cancel_timer, key}, s) do
    case Map.pop(s.timers, key) do
      {{ref, _, _}, timers} ->
        s.ctx.clock.cancel(ref)
        %{s | timers: timers}

      {nil, _} ->
        s
    end
  end

  # User code starts on the next clock tick, in its own process: the parent
  # has finished starting this node's siblings by then (deterministic order),
  # and the node stays free to be stopped while the code runs.
  defp effect({:run_code, key, fun}, s) do
    token = make_ref()
    ref = s.ctx.clock.send_after(self(), {:"$dolphin_code_start", key, token}, 0)
    %{s | code: Map.put(s.code, key, {:pending, ref, token, fun})}
  end

  defp effect(:platform_start, s) do
    %PlatformTask{platform: platform, spec: spec, vehicle: vehicle} = s.task
    # Its loss ends the task: followed from before the look.
    {found, watcher} = Watcher.follow(s.watcher, vehicle)
    s = %{s | watcher: watcher}

    opts = [owner: self(), run: s.run.id, task_id: s.id, clock: s.ctx.clock, source: Context.source(s.ctx), vehicle: vehicle] ++ s.ctx.platform_opts

    case found do
      {:ok, %{connected?: false}} ->
        feed(s, {:platform_start_failed, {:vehicle_lost, vehicle}})

      {:error, :unknown_vehicle} ->
        feed(s, {:platform_start_failed, "vehicle #{vehicle} is unknown"})

      {:ok, _} ->
        try do
          platform.start(spec, vehicle, opts)
        rescue
          e -> {:error, {:exception, e, __STACKTRACE__}}
        end
        |> case do
          {:ok, pid} when is_pid(pid) -> %{s | platform: pid, stop_alias: stoppable(s, pid, platform)}
          {:error, reason} -> feed(s, {:platform_start_failed, reason})
          other -> feed(s, {:platform_start_failed, "#{inspect(platform)}.start/3 returned #{inspect(other)}"})
        end
    end
  end

  defp effect({:platform_stop, reason}, s), do: elem(platform_stop(s, reason), 1)

  defp effect({:emit, event, fields}, s) do
    emit(s, event, fields)
    s
  end

  defp effect({:emit, :condition_met, fields, sensor_reads}, s) do
    emit(s, :condition_met, fields)

    for {v, sensor} <- sensor_reads,
        detection = Dolphin.Engine.Watcher.detection(v, sensor),
        do: emit(s, :sensor_threshold, Dolphin.Sensors.Detection.event_fields(detection, fields.condition, nil))

    s
  end

  defp effect(:continue, s), do: feed(s, :continue)
  defp effect({:finish, result}, s), do: finish(s, result)

  # --- conditions ---

  # The last task id of a subtree: ids are given in pre-order, before the
  # `on` nodes are taken out (Dolphin.Engine.Run.prepare/4), so a subtree's
  # ids are one interval, from its root's to its largest.
  defp last_id(task), do: task |> Task.flatten() |> Enum.map(& &1.id) |> Enum.max()

  # A condition whose reads nobody sees (it calls functions the macros could
  # not see into, or reads live) is re-evaluated on the changes of the
  # vehicles its node's task flies: followed from when it is watched.
  defp follow_flown(s, %{follow: true}) do
    watcher = Enum.reduce(flown(s.task), s.watcher, fn id, w -> elem(Watcher.follow(w, id), 1) end)
    %{s | watcher: watcher}
  end

  defp follow_flown(s, _cond), do: s

  defp flown(%PlatformTask{vehicle: v}) when v != nil, do: [v]
  defp flown(task), do: task |> Task.children() |> Enum.flat_map(&flown/1) |> Enum.uniq()

  # The watched conditions a change may concern, evaluated again in watch
  # order: those that read what changed, those that follow their task's
  # vehicles; all of them on the slow tick.
  defp reevaluate(%{watches: []} = s, _changed), do: s

  defp reevaluate(s, changed) do
    keys = for {key, cond} <- s.watches, concerns?(s, key, cond, changed), do: key

    Enum.reduce(keys, s, fn key, s ->
      case List.keyfind(s.watches, key, 0) do
        nil ->
          s

        {^key, cond} ->
          {result, watcher} = Watcher.evaluate(s.watcher, key, cond)
          s = %{s | watcher: watcher}

          case result do
            {:ok, true} ->
              s = feed(%{s | watches: List.keydelete(s.watches, key, 0)}, {:condition, key})
              # What it read is let go after the reaction, not before: the
              # reaction (stopping a subtree, say) is what is waited for.
              if List.keymember?(s.watches, key, 0), do: s, else: %{s | watcher: Watcher.forget(s.watcher, key)}

            {:ok, false} ->
              s

            {:error, e, _} ->
              finish(s, {:failed, {:condition_error, cond.source, e}})
          end
      end
    end)
  end

  defp concerns?(_s, _key, _cond, :all), do: true
  defp concerns?(_s, key, _cond, {:key, only}), do: key == only
  defp concerns?(_s, _key, %{follow: true}, {:vehicle, _}), do: true
  defp concerns?(s, key, _cond, read), do: Watcher.reads?(s.watcher, key, read)

  defp ensure_tick(%{watches: [_ | _], tick: nil} = s) do
    token = make_ref()
    ref = s.ctx.clock.send_after(self(), {:"$dolphin_tick", token}, s.ctx.tick_ms)
    %{s | tick: {ref, token}}
  end

  defp ensure_tick(s), do: s

  # --- user code ---

  defp spawn_code(s, key, fun) do
    node = self()
    ctx = s.ctx

    :proc_lib.spawn_link(fn ->
      Context.put(ctx)

      result =
        try do
          {:ok, fun.()}
        rescue
          e -> {:error, {:exception, e, __STACKTRACE__}}
        catch
          :exit, reason -> {:error, {:exit, reason}}
          :throw, value -> {:error, {:throw, value}}
        end

      send(node, {:"$dolphin_code", key, self(), result})
    end)
  end

  # A timer that fires before its deadline (the clock slowed down after it
  # was set: it follows SITL vehicles that fall behind) is set again for
  # what is left.
  defp timer_fired(s, key, token, at) do
    case at - s.ctx.clock.now_ms() do
      left when left > 0 ->
        ref = s.ctx.clock.send_after(self(), {:"$dolphin_timer", key, token}, left)
        %{s | timers: Map.put(s.timers, key, {ref, token, at})}

      _ ->
        %{s | timers: Map.delete(s.timers, key)} |> feed({:timeout, key})
    end
  end

  # --- stopping and finishing ---

  # Phase 1 of a stop: nothing more starts; children are told to stop (they
  # all stop at once), user code is killed, the platform task is stopped.
  defp halt(s, reason) do
    Enum.each(s.timers, fn {_, {ref, _, _}} -> s.ctx.clock.cancel(ref) end)
    if s.tick, do: s.ctx.clock.cancel(elem(s.tick, 0))
    kill_code(s)
    Enum.each(in_start_order(s), &stop_node(&1.pid, reason))
    {outcome, s} = platform_stop(s, reason)
    Enum.each(Map.keys(s.elsewhere), &Conditions.unwatch(s.run.conditions, &1))
    %{s | timers: %{}, tick: nil, watches: [], elsewhere: %{}, code: %{}, halted: outcome}
  end

  defp kill_code(s) do
    for {_key, {:pending, ref, _, _}} <- s.code, do: s.ctx.clock.cancel(ref)

    for {_key, {:running, pid}} <- s.code do
      Process.exit(pid, :kill)
      # Runs the code started (a nested execute) stop their own platform
      # tasks when it dies; wait for them, so nothing outlives this node.
      Dolphin.Engine.Run.await_runs_of(pid, s.ctx.clock.real_ms(s.ctx.stop_timeout_ms * 2))
    end
  end

  # Phase 2: children's results in start order, then this node's.
  defp finish_stopped(s, reason, report?) do
    results = Enum.map(in_start_order(s), &collected(s, &1))
    platform = if match?({:error, _}, s.halted), do: [{:failed, elem(s.halted, 1)}], else: []

    result =
      Enum.find(platform ++ results, :stopped, &match?({:failed, _}, &1))
      |> wrap(s)

    emit_finished(s, result, reason)
    if report?, do: send(s.parent, {:"$dolphin_result", self(), result})
    end_node()
  end

  defp collected(s, %{pid: pid, task: task}) do
    case collect(pid, s.ctx) do
      {:ok, result} -> result
      {:error, reason} -> {:failed, failure(task, reason)}
    end
  end

  defp finish(s, result) do
    # Whatever still runs under this node stops first (after a condition
    # error, say): nothing outlives its parent. No timer outlives it either.
    s = halt(s, :stopped)
    Enum.each(in_start_order(s), &collected(s, &1))
    result = wrap(result, s)
    emit_finished(s, result, nil)

    if s.acked,
      do: send(s.parent, {:"$dolphin_result", self(), result}),
      else: send(s.parent, {:"$dolphin_started", self(), {:finished, result}})

    end_node()
  end

  defp wrap({:failed, %Failure{}} = failed, _s), do: failed
  defp wrap({:failed, reason}, s), do: {:failed, failure(s.task, reason)}
  defp wrap(result, _s), do: result

  defp emit_finished(s, result, stop_reason) do
    {name, reason} =
      case result do
        :done -> {:done, nil}
        :stopped -> {:stopped, Failure.format_reason(stop_reason)}
        {:failed, f} -> {:failed, Failure.message(f)}
      end

    emit(s, :task_finished, %{parent_id: s.parent_id, kind: s.kind, name: s.name, vehicle: s.vehicle, result: name, reason: reason})
  end

  # Stops the platform task (if it runs), bounded; {:ok | {:error, reason}, s}.
  # (Its answer to a stop sent by another process may have come already.)
  defp platform_stop(%{platform: nil} = s, _reason), do: {s.stop_outcome || :ok, s}

  defp platform_stop(%{platform: pid, task: %PlatformTask{platform: platform}} = s, reason) do
    outcome =
      cond do
        s.stop_alias == nil -> stop_in_helper(pid, platform, reason, s.ctx)
        Stops.claim(s.id) -> stop_by_request(pid, platform.stop_request(reason), s.ctx)
        true -> await_stop(pid, s.stop_alias, s.ctx)
      end

    {outcome, platform_ended(s)}
  end

  # A platform that answers a stop request may be sent its stop by the run's
  # conditions process (Dolphin.Engine.Stops): the alias its answer comes to.
  defp stoppable(s, pid, platform) do
    if function_exported?(platform, :stop_request, 1), do: Stops.register(s.id, pid, platform, s.run.id)
  end

  defp platform_ended(s) do
    if s.stop_alias, do: Stops.forget(s.id, s.stop_alias)
    %{s | platform: nil, stop_alias: nil}
  end

  # The answer to the stop the run's conditions process sent, bounded as the
  # leaf's own request is.
  defp await_stop(pid, alias, ctx) do
    case Stops.await(pid, alias, ctx.clock.real_ms(ctx.stop_timeout_ms)) do
      {:reply, result} ->
        stop_outcome(result)

      :gone ->
        :ok

      :timeout ->
        Process.exit(pid, :kill)
        {:error, {:stop_timeout, ctx.stop_timeout_ms}}
    end
  end

  # The platform's process answers a call to stop: the request is sent from
  # here and its reply awaited, bounded. No process is spawned for it, which
  # a burst of a thousand stops feels. A process gone before it answered had
  # finished or failed already (what `stop/2` of both platforms says too).
  defp stop_by_request(pid, request, ctx) do
    req = :gen_server.send_request(pid, request)

    case :gen_server.receive_response(req, ctx.clock.real_ms(ctx.stop_timeout_ms)) do
      {:reply, result} ->
        stop_outcome(result)

      {:error, {_exit, ^pid}} ->
        :ok

      # (The request is abandoned: no late reply or :DOWN of it comes.)
      :timeout ->
        Process.exit(pid, :kill)
        {:error, {:stop_timeout, ctx.stop_timeout_ms}}
    end
  end

  # Any other platform's stop/2 runs in a helper, so that its wait is bounded
  # whatever the function does.
  defp stop_in_helper(pid, platform, reason, ctx) do
    me = self()

    {helper, mon} =
      :proc_lib.spawn_opt(
        fn ->
          result =
            try do
              platform.stop(pid, reason)
            rescue
              e -> {:error, {:exception, e, __STACKTRACE__}}
            catch
              kind, why -> {:error, {kind, why}}
            end

          send(me, {:"$dolphin_stopped", self(), result})
        end,
        [:monitor]
      )

    outcome =
      receive do
        {:"$dolphin_stopped", ^helper, result} -> stop_outcome(result)
        {:DOWN, ^mon, :process, ^helper, why} -> {:error, {:stop_failed, {:exit, why}}}
      after
        ctx.clock.real_ms(ctx.stop_timeout_ms) ->
          Process.exit(helper, :kill)
          Process.exit(pid, :kill)
          {:error, {:stop_timeout, ctx.stop_timeout_ms}}
      end

    Process.demonitor(mon, [:flush])
    outcome
  end

  # What a platform's stop returned (stop/2, or the reply to stop_request/1).
  defp stop_outcome(:ok), do: :ok
  defp stop_outcome({:error, why}), do: {:error, {:stop_failed, why}}
  defp stop_outcome(other), do: {:error, {:stop_failed, other}}

  defp emit(s, event, fields),
    do: Dolphin.Events.emit(event, Map.merge(%{run: s.run.id, task_id: s.id}, fields), s.ctx.clock.now_ms())

  defp vehicles_in(task), do: for(%PlatformTask{vehicle: v} when v != nil <- Task.flatten(task), do: v) |> Enum.uniq()
end
