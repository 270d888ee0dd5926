defmodule Dolphin.Engine.Reference do
  @moduledoc """
  A small, pure reference interpreter of DSL.md for the property test's task
  language, independent of the engine: a discrete-event simulation with a
  timer queue (due time, then the order timers were set) and a synchronous,
  depth-first cascade at each instant, following the order the engine
  documents (a node starts before its children; a child that ends as it
  starts is handled at once; a stopped subtree ends children first, in start
  order; user code starts on the next clock tick).

  Tasks (each with a unique name):

      {:idle, name, d} | {:test, name, d, :done | :fail} | {:action, name, :ok | :raise}
      {:cond, name, k} | {:seq, name, [t]} | {:conc, name, [t]} | {:until, name, t, k}
      {:during, name, d, t} | {:wait, name, k, t | nil} | {:one_of, name, [{k, t}]}
      {:all_of, name, [{k, t}]} | {:watch, name, t, :ignore | :propagate | {:handler, t | nil}}

  Condition `k` holds from its flip time on (`flips`: `%{k => 0 | ms | :never}`).
  Events: `{t, :started, name}`, `{t, :met, name, branch}`,
  `{t, :finished, name, :done | :stopped | {:failed, origin}}`.
  """

  def run(tree, flips) do
    st = %{now: 0, seq: 0, timers: [], vars: Map.new(flips, fn {k, f} -> {k, f == 0} end), watching: %{}, nodes: %{}, events: [], result: nil, root: nil}
    st = Enum.reduce(Enum.sort(flips), st, fn {k, f}, st -> if is_integer(f) and f > 0, do: timer(st, f, :flips, {:flip, k}), else: st end)
    %{st | root: elem(tree, 1)} |> start(tree, :root) |> loop()
  end

  defp loop(%{result: r} = st) when r != nil, do: {r, Enum.reverse(st.events)}

  # Nothing left to happen (a condition that never holds): the operator
  # stops the run, children first.
  defp loop(%{timers: []} = st) do
    st = stop_subtree(st, st.root)
    {:stopped, Enum.reverse(st.events)}
  end

  defp loop(st) do
    [{due, _seq, _owner, action} | rest] = Enum.sort_by(st.timers, fn {due, seq, _, _} -> {due, seq} end)
    st = %{st | now: due, timers: rest}
    st |> fire(action) |> loop()
  end

  defp timer(st, ms, owner, action), do: %{st | seq: st.seq + 1, timers: st.timers ++ [{st.now + ms, st.seq, owner, action}]}
  defp emit(st, event), do: %{st | events: [Tuple.insert_at(event, 0, st.now) | st.events]}
  defp node(st, name), do: st.nodes[name]
  defp put(st, name, fun), do: %{st | nodes: Map.update!(st.nodes, name, fun)}
  defp active?(st, name), do: Map.has_key?(st.nodes, name)
  defp watch(st, k, name, branch), do: %{st | watching: Map.put(st.watching, k, {name, branch})}
  defp unwatch(st, k), do: %{st | watching: Map.delete(st.watching, k)}
  defp completed({:failed, _} = f), do: f
  defp completed(_), do: :done

  # --- starting ---

  defp start(st, ast, parent) do
    name = elem(ast, 1)
    st = emit(st, {:started, name})
    st = %{st | nodes: Map.put(st.nodes, name, %{ast: ast, parent: parent, running: [], data: %{}})}
    init(st, ast)
  end

  defp start_child(st, parent, child) do
    st = put(st, parent, &%{&1 | running: &1.running ++ [elem(child, 1)]})
    start(st, child, parent)
  end

  defp init(st, {:idle, name, d}), do: timer(st, d, name, {:end, name})
  defp init(st, {:test, name, d, _}), do: timer(st, d, name, {:end, name})
  defp init(st, {:action, name, _}), do: timer(st, 0, name, {:code, name})

  defp init(st, {:cond, name, k}) do
    if st.vars[k], do: st |> emit({:met, name, nil}) |> finish(name, :done), else: watch(st, k, name, nil)
  end

  defp init(st, {:seq, name, [first | _]}), do: start_child(st, name, first)

  defp init(st, {:conc, name, ts}), do: start_conc(put(st, name, &%{&1 | data: %{next: 0, failure: nil, n: length(ts)}}), name)

  defp init(st, {:until, name, t, k}) do
    if st.vars[k],
      do: st |> emit({:met, name, nil}) |> finish(name, :done),
      else: st |> watch(k, name, nil) |> put(name, &%{&1 | data: %{met: false}}) |> start_child(name, t)
  end

  defp init(st, {:during, name, d, t}), do: st |> put(name, &%{&1 | data: %{expired: false}}) |> timer(d, name, {:end, name}) |> start_child(name, t)

  defp init(st, {:wait, name, k, t}) do
    if st.vars[k], do: st |> emit({:met, name, nil}) |> go(name, t), else: watch(st, k, name, nil)
  end

  defp init(st, {:one_of, name, branches}) do
    case Enum.find_index(branches, fn {k, _} -> st.vars[k] end) do
      nil -> branches |> Enum.with_index() |> Enum.reduce(st, fn {{k, _}, i}, st -> watch(st, k, name, i) end)
      i -> st |> emit({:met, name, i}) |> start_child(name, elem(Enum.at(branches, i), 1))
    end
  end

  defp init(st, {:all_of, name, branches}) do
    st = put(st, name, &%{&1 | data: %{left: length(branches), failure: nil, waiting: []}})

    branches
    |> Enum.with_index()
    |> Enum.reduce_while(st, fn {{k, t}, i}, st ->
      cond do
        not active?(st, name) or node(st, name).data.failure -> {:halt, st}
        st.vars[k] -> {:cont, st |> emit({:met, name, i}) |> start_child(name, t)}
        true -> {:cont, st |> watch(k, name, i) |> put(name, &put_in(&1.data.waiting, &1.data.waiting ++ [k]))}
      end
    end)
  end

  defp init(st, {:watch, name, t, _}), do: start_child(st, name, t)

  defp go(st, name, nil), do: finish(st, name, :done)
  defp go(st, name, t), do: start_child(st, name, t)

  defp start_conc(st, name) do
    %{data: %{next: i, n: n, failure: f}} = node(st, name)

    if f == nil and i < n do
      child = Enum.at(elem(node(st, name).ast, 2), i)
      st = st |> put(name, &put_in(&1.data.next, i + 1)) |> start_child(name, child)
      if active?(st, name), do: start_conc(st, name), else: st
    else
      st
    end
  end

  # --- ending ---

  defp finish(st, name, result) do
    %{parent: parent} = node(st, name)
    st = %{st | timers: Enum.reject(st.timers, &(elem(&1, 2) == name)), watching: Map.reject(st.watching, fn {_, {n, _}} -> n == name end)}
    st = emit(st, {:finished, name, result})
    st = %{st | nodes: Map.delete(st.nodes, name)}
    if parent == :root, do: %{st | result: result}, else: child_finished(st, parent, name, result)
  end

  # A subtree stopped from above: children first, in start order; no parent callback.
  defp stop_subtree(st, name) do
    %{running: running} = node(st, name)
    st = %{st | timers: Enum.reject(st.timers, &(elem(&1, 2) == name)), watching: Map.reject(st.watching, fn {_, {n, _}} -> n == name end)}
    st = Enum.reduce(running, st, &stop_subtree(&2, &1))
    st = emit(st, {:finished, name, :stopped})
    %{st | nodes: Map.delete(st.nodes, name)}
  end

  defp stop_children(st, parent, children) do
    Enum.reduce(children, st, fn child, st ->
      if active?(st, child), do: st |> stop_subtree(child) |> child_finished(parent, child, :stopped), else: st
    end)
  end

  defp child_finished(st, p, child, r) do
    st = put(st, p, &%{&1 | running: List.delete(&1.running, child)})
    react(st, node(st, p).ast, child, r)
  end

  defp react(st, {:seq, name, ts}, child, r) do
    rest = ts |> Enum.drop_while(&(elem(&1, 1) != child)) |> tl()

    case {r, rest} do
      {{:failed, _}, _} -> finish(st, name, r)
      {_, []} -> finish(st, name, :done)
      {_, [next | _]} -> start_child(st, name, next)
    end
  end

  defp react(st, {:conc, name, _}, _child, r) do
    %{running: running, data: %{failure: f, next: next, n: n}} = node(st, name)

    case {r, f, running} do
      {{:failed, _}, nil, []} -> finish(st, name, r)
      {{:failed, _}, nil, others} -> st |> put(name, &put_in(&1.data.failure, r)) |> stop_children(name, others)
      {_, nil, []} when next == n -> finish(st, name, :done)
      {_, nil, _} -> st
      {_, f, []} -> finish(st, name, f)
      _ -> st
    end
  end

  defp react(st, {:until, name, _, k}, _child, r) do
    if node(st, name).data.met, do: finish(st, name, completed(r)), else: st |> unwatch(k) |> finish(name, completed(r))
  end

  defp react(st, {:during, name, _, _}, _child, r), do: finish(st, name, completed(r))
  defp react(st, {:wait, name, _, _}, _child, r), do: finish(st, name, completed(r))
  defp react(st, {:one_of, name, _}, _child, r), do: finish(st, name, completed(r))

  defp react(st, {:all_of, name, _}, _child, r) do
    st = put(st, name, &put_in(&1.data.left, &1.data.left - 1))
    %{running: running, data: %{failure: f, left: left, waiting: waiting}} = node(st, name)

    case {r, f} do
      {{:failed, _}, nil} ->
        st = waiting |> Enum.reduce(st, &unwatch(&2, &1)) |> put(name, &put_in(&1.data.waiting, []))
        if running == [], do: finish(st, name, r), else: st |> put(name, &put_in(&1.data.failure, r)) |> stop_children(name, running)

      {_, nil} ->
        if left == 0, do: finish(st, name, :done), else: st

      {_, f} ->
        if running == [], do: finish(st, name, f), else: st
    end
  end

  defp react(st, {:watch, name, t, on_error}, child, r) do
    cond do
      child != elem(t, 1) -> finish(st, name, completed(r))
      not match?({:failed, _}, r) -> finish(st, name, :done)
      on_error == :ignore -> finish(st, name, :done)
      on_error == :propagate -> finish(st, name, r)
      true -> timer(st, 0, name, {:code, name})
    end
  end

  # --- time ---

  defp fire(st, {:flip, k}) do
    st = %{st | vars: Map.put(st.vars, k, true)}

    case st.watching[k] do
      nil -> st
      {name, branch} -> st |> unwatch(k) |> condition(node(st, name).ast, branch)
    end
  end

  defp fire(st, {:end, name}) do
    case node(st, name).ast do
      {:idle, _, _} -> finish(st, name, :done)
      {:test, _, _, :done} -> finish(st, name, :done)
      {:test, _, _, :fail} -> finish(st, name, {:failed, name})
      {:during, _, _, t} -> st |> put(name, &put_in(&1.data.expired, true)) |> stop_children(name, Enum.filter([elem(t, 1)], &active?(st, &1)))
    end
  end

  defp fire(st, {:code, name}) do
    case node(st, name).ast do
      {:action, _, :ok} -> finish(st, name, :done)
      {:action, _, :raise} -> finish(st, name, {:failed, name})
      {:watch, _, _, {:handler, nil}} -> finish(st, name, :done)
      {:watch, _, _, {:handler, h}} -> start_child(st, name, h)
    end
  end

  defp condition(st, {:cond, name, _}, _), do: st |> emit({:met, name, nil}) |> finish(name, :done)

  defp condition(st, {:until, name, t, _}, _) do
    st = st |> emit({:met, name, nil}) |> put(name, &put_in(&1.data.met, true))
    stop_children(st, name, [elem(t, 1)])
  end

  defp condition(st, {:wait, name, _, t}, _), do: st |> emit({:met, name, nil}) |> go(name, t)

  defp condition(st, {:one_of, name, branches}, i) do
    st = Enum.reduce(branches, st, fn {k, _}, st -> if match?({^name, _}, st.watching[k]), do: unwatch(st, k), else: st end)
    st |> emit({:met, name, i}) |> start_child(name, elem(Enum.at(branches, i), 1))
  end

  defp condition(st, {:all_of, name, branches}, i) do
    {k, t} = Enum.at(branches, i)
    st |> put(name, &put_in(&1.data.waiting, List.delete(&1.data.waiting, k))) |> emit({:met, name, i}) |> start_child(name, t)
  end
end

defmodule Dolphin.Engine.PropertyTest do
  @moduledoc false
  # Random task trees over the fake platform, run by the engine on a manual
  # clock, against the reference interpreter: same result, same events in
  # the same order at the same clock times.
  use Dolphin.EngineCase, async: false

  import Dolphin.Property

  alias Dolphin.Engine.{Cond, Reference}
  alias Dolphin.Test.ManualClock

  @vehicles 100
  @cond_base 500_000
  # Clock time past which only the conditions' slow ticks remain: the run is stuck.
  @horizon 100_000

  setup ctx do
    start_supervised!(ManualClock)
    platform = fake_vehicles(ctx, @vehicles, pick: true)
    for k <- 1..300, do: FakeSource.add(ctx.source, @cond_base + k, type: :ugv, battery: 1.0)
    {:ok, platform: platform}
  end

  test "the engine does what the reference interpreter of DSL.md predicts", ctx do
    check(
      forall(tree(), fn raw ->
        {tree, flips} = label(raw)
        {expected_result, expected} = Reference.run(tree, flips)
        {result, events} = run_engine(ctx, tree, flips)

        assert normalise(result) == expected_result, "result differs for #{inspect(tree)} with #{inspect(flips)}"
        assert comparable(events) == expected
        assert_distinct_vehicles(events)
      end),
      numtests: 200,
      max_size: 24
    )
  end

  # --- generators (PropEr) ---

  defp t, do: :proper_types

  defp tree, do: t().sized(&tree/1)

  defp tree(size) when size <= 1, do: leaf()
  defp tree(size), do: t().frequency([{2, leaf()}, {5, t().lazy(fn -> composite(div(size * 2, 3)) end)}])

  defp leaf do
    t().frequency([
      {2, t().tuple([:idle, dur()])},
      {3, t().tuple([:test, dur(), t().frequency([{4, :done}, {1, :fail}])])},
      {1, t().tuple([:action, t().frequency([{3, :ok}, {1, :raise}])])},
      {2, t().tuple([:cond, flip()])}
    ])
  end

  defp composite(size) do
    sub = tree(size)
    some = t().bind(t().integer(1, 3), fn n -> t().vector(n, sub) end, false)
    branches = t().bind(t().integer(1, 3), fn n -> t().vector(n, t().tuple([flip(), sub])) end, false)

    t().frequency([
      {3, t().tuple([:seq, some])},
      {3, t().tuple([:conc, some])},
      {2, t().tuple([:until, sub, flip()])},
      {2, t().tuple([:during, dur(), sub])},
      {1, t().tuple([:wait, flip(), t().oneof([nil, sub])])},
      {1, t().tuple([:one_of, branches])},
      {1, t().tuple([:all_of, branches])},
      {2, t().tuple([:watch, sub, t().oneof([:ignore, :propagate, t().tuple([:handler, t().oneof([nil, sub])])])])}
    ])
  end

  # Durations and flip times on a 10 ms grid: ties are frequent, and broken by the order timers were set.
  defp dur, do: t().bind(t().integer(0, 5), &(&1 * 10), false)
  defp flip, do: t().frequency([{1, 0}, {4, t().bind(t().integer(1, 6), &(&1 * 10), false)}, {1, :never}])

  # Names every node ("n1", ... in pre-order) and every condition (1, 2, ...).
  defp label(raw) do
    {tree, {_, flips}} = lab(raw, {1, %{}})
    {tree, flips}
  end

  defp lab({:idle, d}, {i, f}), do: {{:idle, "n#{i}", d}, {i + 1, f}}
  defp lab({:test, d, r}, {i, f}), do: {{:test, "n#{i}", d, r}, {i + 1, f}}
  defp lab({:action, r}, {i, f}), do: {{:action, "n#{i}", r}, {i + 1, f}}
  defp lab({:cond, flip}, acc), do: with({name, k, acc} <- named_cond(acc, flip), do: {{:cond, name, k}, acc})
  defp lab({:seq, ts}, {i, f}), do: with({ts, acc} <- Enum.map_reduce(ts, {i + 1, f}, &lab/2), do: {{:seq, "n#{i}", ts}, acc})
  defp lab({:conc, ts}, {i, f}), do: with({ts, acc} <- Enum.map_reduce(ts, {i + 1, f}, &lab/2), do: {{:conc, "n#{i}", ts}, acc})

  defp lab({:until, t, flip}, acc) do
    {name, k, acc} = named_cond(acc, flip)
    {t, acc} = lab(t, acc)
    {{:until, name, t, k}, acc}
  end

  defp lab({:during, d, t}, {i, f}), do: with({t, acc} <- lab(t, {i + 1, f}), do: {{:during, "n#{i}", d, t}, acc})

  defp lab({:wait, flip, t}, acc) do
    {name, k, acc} = named_cond(acc, flip)
    {t, acc} = if t, do: lab(t, acc), else: {nil, acc}
    {{:wait, name, k, t}, acc}
  end

  defp lab({kind, branches}, {i, f}) when kind in [:one_of, :all_of] do
    {branches, acc} =
      Enum.map_reduce(branches, {i + 1, f}, fn {flip, t}, {j, f} ->
        k = map_size(f) + 1
        {t, acc} = lab(t, {j, Map.put(f, k, flip)})
        {{k, t}, acc}
      end)

    {{kind, "n#{i}", branches}, acc}
  end

  defp lab({:watch, t, h}, {i, f}) do
    {t, acc} = lab(t, {i + 1, f})

    case h do
      {:handler, ht} when ht != nil ->
        {ht, acc} = lab(ht, acc)
        {{:watch, "n#{i}", t, {:handler, ht}}, acc}

      h ->
        {{:watch, "n#{i}", t, h}, acc}
    end
  end

  defp named_cond({i, f}, flip) do
    k = map_size(f) + 1
    {"n#{i}", k, {i + 1, Map.put(f, k, flip)}}
  end

  # --- the engine's side ---

  defp run_engine(ctx, tree, flips) do
    for {k, _} <- flips, do: FakeSource.set(ctx.source, @cond_base + k, battery: if(flips[k] == 0, do: 0.1, else: 1.0))
    ManualClock.reset()

    for {k, at} <- Enum.sort(flips), is_integer(at) and at > 0 do
      ManualClock.at(at, fn -> FakeSource.set(ctx.source, @cond_base + k, battery: 0.1) end)
    end

    {:ok, run} = start(engine(tree), clock: ManualClock, tick_ms: 1_000_000_000)
    done = fn ->
      receive do
        {Dolphin.Engine, ^run, result} -> {:ok, result}
      after
        0 -> nil
      end
    end

    # Waiting on a condition that never holds, with nothing else to come:
    # the operator stops the run.
    result =
      case ManualClock.run_until(done, @horizon) do
        {:ok, result} ->
          result

        :stuck ->
          :ok = Dolphin.Engine.stop(run)
          {:ok, result} = ManualClock.run_until(done, @horizon)
          result
      end

    {result, events_of(run)}
  end

  defp engine({:idle, name, d}), do: idle(d, name: name)
  defp engine({:test, name, d, r}), do: FakePlatform.task(name, duration: d, result: if(r == :fail, do: {:fail, :boom}, else: :done))
  defp engine({:action, name, :ok}), do: action(fn -> :ok end, name: name)
  defp engine({:action, name, :raise}), do: action(fn -> raise "boom" end, name: name)
  defp engine({:cond, name, k}), do: condition(kcond(k), name: name)
  defp engine({:seq, name, ts}), do: sequence(Enum.map(ts, &engine/1), name: name)
  defp engine({:conc, name, ts}), do: concurrent(Enum.map(ts, &engine/1), name: name)
  defp engine({:until, name, t, k}), do: until(engine(t), kcond(k), name: name)
  defp engine({:during, name, d, t}), do: during(d, engine(t), name: name)
  defp engine({:wait, name, k, t}), do: wait_for(kcond(k), t && engine(t), name: name)
  defp engine({:one_of, name, bs}), do: one_of(for({k, t} <- bs, do: {kcond(k), engine(t)}), name: name)
  defp engine({:all_of, name, bs}), do: all_of(for({k, t} <- bs, do: {kcond(k), engine(t)}), name: name)
  defp engine({:watch, name, t, {:handler, nil}}), do: watch(engine(t), on_error: fn _ -> :ok end, name: name)

  defp engine({:watch, name, t, {:handler, h}}) do
    handler_task = engine(h)
    watch(engine(t), on_error: fn _ -> handler_task end, name: name)
  end

  defp engine({:watch, name, t, h}), do: watch(engine(t), on_error: h, name: name)

  defp kcond(k) do
    id = @cond_base + k
    Cond.new(fn snap -> Dolphin.Engine.Snapshot.battery(snap, id) < 0.5 end, source: "k#{k}")
  end

  defp normalise({:ok, :done}), do: :done
  defp normalise({:ok, :stopped}), do: :stopped
  defp normalise({:error, %Failure{name: name}}), do: {:failed, name}
  defp normalise(other), do: other

  defp comparable(events) do
    names = for %{event: :task_started, task_id: id, name: n} <- events, into: %{}, do: {id, n}

    Enum.flat_map(events, fn
      %{event: :task_started, at_ms: t, name: n} -> [{t, :started, n}]
      %{event: :condition_met, at_ms: t, task_id: id, branch: b} -> [{t, :met, names[id], b}]
      %{event: :task_finished, at_ms: t, name: n, result: :failed, reason: why} -> [{t, :finished, n, {:failed, origin(why)}}]
      %{event: :task_finished, at_ms: t, name: n, result: r} -> [{t, :finished, n, r}]
      _ -> []
    end)
  end

  defp origin(reason), do: with([_, name] <- Regex.run(~r/^\w+ "([^"]+)"/, reason), do: name)

  # Platform tasks running at the same time never share a vehicle.
  defp assert_distinct_vehicles(events) do
    Enum.reduce(events, %{}, fn
      %{event: :task_started, vehicle: v, name: n}, busy when v != nil ->
        refute Map.has_key?(busy, v), "#{n} started on vehicle #{v}, which #{busy[v]} was using"
        Map.put(busy, v, n)

      %{event: :task_finished, vehicle: v}, busy when v != nil ->
        Map.delete(busy, v)

      _, busy ->
        busy
    end)
  end
end
