defmodule Dolphin.Engine.Conditions do
  @moduledoc false
  # A run's conditions process: where the conditions of the run's `until`
  # nodes are re-evaluated while their tasks run. Started by the run
  # (Dolphin.Engine.Run), linked to it, one per run.
  #
  # Why one process: a change of one vehicle that a thousand `until`s read
  # used to wake a thousand `until` processes, each of which woke its leaf,
  # which woke its platform — three waves of a thousand wake-ups before the
  # last vehicle was told to hold. Here the change wakes this process once;
  # it evaluates every condition that reads what changed, in the order they
  # were watched, then sends each platform under an `until` whose condition
  # holds its stop (Dolphin.Engine.Stops), all of them before anything else
  # runs; only then does it tell the `until`s, which say `condition_met` and
  # stop their subtrees as before (the leaves await the answers to the stops
  # already sent). An `until` that has ended meanwhile says nothing.
  #
  # The platforms under an `until` are those of the tasks whose ids lie in
  # its subtree's interval: a subtree started later (`reassign`'s,
  # `on_sensor`'s missions) has ids of its own and is stopped the usual way,
  # by its leaves when the `until` stops them.
  #
  # The conditions run here are those the script macros compile (readers,
  # arithmetic, comparisons) and functions of the snapshot given to
  # Dolphin.Engine.Cond.new/2: one that took long would hold up every
  # `until` of the run, so a pass that goes on past @high_ms gives up its
  # priority (below).
  #
  # What a condition reads is followed here exactly as a node does it
  # (Dolphin.Engine.Watcher); the slow tick re-evaluates them all. A
  # condition that raises, or that follows the vehicles its task flies
  # (`follow: true`, which only its node knows), is never evaluated here:
  # its node keeps it (the first by `{:"$dolphin_condition_back", key}`).
  #
  # Messages: {:watch, node, key, cond, task_id, last_id} (the `until` of
  # task `task_id`, whose subtree's ids end at `last_id`), {:unwatch, node,
  # key}; to the node: {:"$dolphin_condition", key} once its condition held
  # (watched no longer), {:"$dolphin_condition_back", key}. A proc_lib
  # process answering OTP's system messages (:sys.get_state/1 shows what it
  # watches), whose :sys parent is the run.

  alias Dolphin.Engine.{Context, Stops, Watcher}

  # How many conditions the slow tick re-evaluates between two looks at the mailbox.
  @tick_part 100
  # How long (real ms) a pass keeps high priority.
  @high_ms 20

  @doc false
  # Started in the run's process (its group leader: a dry run knows its processes by it).
  def start_link(ctx, run_id) do
    parent = self()
    # A young heap that holds a burst's work without collecting in the middle of it.
    :proc_lib.spawn_opt(fn -> init(ctx, run_id, parent) end, [:link, min_heap_size: 32_768])
  end

  @doc false
  def watch(hub, key, cond, task_id, last_id),
    do: send(hub, {:watch, self(), key, cond, task_id, last_id})

  @doc false
  def unwatch(hub, key), do: send(hub, {:unwatch, self(), key})

  defp init(ctx, run_id, parent) do
    Process.flag(:trap_exit, true)
    Context.put(ctx)

    loop(%{
      ctx: ctx,
      run_id: run_id,
      parent: parent,
      watcher: Watcher.new(Context.source(ctx), ctx.signals),
      # {node, key} => %{cond, task_id, last_id, n}; n orders them as watched.
      watched: %{},
      n: 0,
      # read => %{{node, key} => n}: the conditions that read it (Watcher.reads/2 of each).
      readers: %{},
      # node => {monitor, its keys watched}
      nodes: %{},
      tick: nil
    })
  end

  defp loop(s) do
    parent = s.parent

    receive do
      {:system, from, request} ->
        :sys.handle_system_msg(request, from, parent, __MODULE__, [], s)

      {:dolphin, {:vehicle, id}, {:view, view}} ->
        s = %{s | watcher: Watcher.update(s.watcher, view)}
        s |> evaluate(readers(s, {:vehicle, id})) |> loop()

      {:dolphin, {:dolphin_signals, table}, _} ->
        s |> evaluate(readers(s, {:signals, table})) |> loop()

      {:tick, token} ->
        case s.tick do
          {_ref, ^token} ->
            %{s | tick: :running}
            |> on_tick(Enum.sort(for {k, w} <- s.watched, do: {w.n, k}))
            |> loop()

          _ ->
            loop(s)
        end

      {:tick_rest, keys} ->
        loop(on_tick(s, keys))

      {:watch, node, key, cond, task_id, last_id} ->
        k = {node, key}

        s = %{
          s
          | watched:
              Map.put(s.watched, k, %{cond: cond, task_id: task_id, last_id: last_id, n: s.n}),
            n: s.n + 1
        }

        s = add_node(s, node, key)
        # Evaluated at once, on what is read now (subscribed first): a change
        # between the node's own check and this is not missed.
        s |> evaluate([{s.n - 1, k}]) |> ensure_tick() |> loop()

      {:unwatch, node, key} ->
        loop(drop(s, {node, key}))

      {:DOWN, _ref, :process, node, _} ->
        {{_ref, keys}, nodes} = Map.pop(s.nodes, node, {nil, MapSet.new()})
        keys |> Enum.reduce(%{s | nodes: nodes}, &drop(&2, {node, &1})) |> loop()

      {:EXIT, ^parent, _} ->
        :ok

      _other ->
        loop(s)
    end
  end

  # --- :sys callbacks ---

  @doc false
  def system_continue(_parent, _debug, s), do: loop(s)

  @doc false
  def system_terminate(reason, _parent, _debug, _s), do: exit(reason)

  use Dolphin.Engine.SysState

  # The conditions that read `read`, as {n, key}, in watch order.
  defp readers(s, read) do
    case s.readers do
      %{^read => keys} -> Enum.sort(for {k, n} <- keys, do: {n, k})
      _ -> []
    end
  end

  # The slow tick's re-evaluation of every condition, a part at a time:
  # what comes in meanwhile (a vehicle's change) is not kept waiting behind
  # a thousand evaluations. The next tick is set once the last part is done.
  defp on_tick(s, keys) do
    {now, rest} = Enum.split(keys, @tick_part)
    s = evaluate(s, now)

    case rest do
      [] -> ensure_tick(%{s | tick: nil})
      _ -> send(self(), {:tick_rest, rest}) && s
    end
  end

  # Evaluates the conditions given as {n, key} in watch order (n), those
  # still watched; sends the stops of each that holds at once, and once all
  # are evaluated tells their nodes: every stop is on its way before any
  # `until` or leaf is woken.
  defp evaluate(s, keys) do
    # Until every stop is sent, the processes those stops wake (and anything
    # else of normal priority) wait: a slice of this work is not put behind
    # a thousand platforms in the run queue. (For @high_ms at most.)
    Process.flag(:priority, :high)
    high_until = System.monotonic_time(:millisecond) + @high_ms

    {met, s} =
      Enum.reduce(keys, {[], s}, fn {_n, k}, acc ->
        acc = evaluate_one(k, acc)
        if System.monotonic_time(:millisecond) > high_until, do: Process.flag(:priority, :normal)
        acc
      end)

    Process.flag(:priority, :normal)

    met
    |> Enum.reverse()
    |> Enum.reduce(s, fn {{node, key} = k, _w}, s ->
      send(node, {:"$dolphin_condition", key})
      drop(s, k)
    end)
  end

  defp evaluate_one(k, {met, s}) do
    case s.watched do
      %{^k => w} ->
        {result, watcher} = Watcher.evaluate(s.watcher, k, w.cond)
        # (A watcher that read nothing new comes back the same term: compared at once.)
        s = if watcher === s.watcher, do: s, else: index(%{s | watcher: watcher}, k, w.n)

        case result do
          {:ok, true} ->
            Stops.stop_under(w.task_id, w.last_id, {:condition_met, w.task_id})
            {[{k, w} | met], s}

          {:ok, false} ->
            {met, s}

          # Its node evaluates it again, and fails with the error as it always did.
          {:error, _, _} ->
            {met, give_back(s, k)}
        end

      # No longer watched (a part of the tick's, after its node let it go).
      _ ->
        {met, s}
    end
  end

  defp give_back(s, {node, key} = k) do
    send(node, {:"$dolphin_condition_back", key})
    drop(s, k)
  end

  # No longer watched: what no other condition reads is let go (found from
  # the index, not by going through every condition: a thousand conditions
  # ending one by one would make that quadratic).
  defp drop(s, {node, key} = k) do
    case Map.pop(s.watched, k) do
      {nil, _} ->
        s

      {_w, watched} ->
        {readers, unread} =
          Enum.reduce(Watcher.reads(s.watcher, k), {s.readers, []}, fn read, {readers, unread} ->
            case readers |> Map.get(read, %{}) |> Map.delete(k) do
              empty when map_size(empty) == 0 -> {Map.delete(readers, read), [read | unread]}
              keys -> {Map.put(readers, read, keys), unread}
            end
          end)

        nodes =
          case s.nodes do
            %{^node => {ref, keys}} -> Map.put(s.nodes, node, {ref, MapSet.delete(keys, key)})
            nodes -> nodes
          end

        %{
          s
          | watched: watched,
            readers: readers,
            nodes: nodes,
            watcher: Watcher.forget(s.watcher, k, unread)
        }
    end
  end

  # What a condition read, indexed (it may read more on each evaluation; it
  # keeps what it read while watched, as a node's watcher does).
  defp index(s, k, n) do
    readers =
      Enum.reduce(Watcher.reads(s.watcher, k), s.readers, fn read, readers ->
        Map.update(readers, read, %{k => n}, &Map.put(&1, k, n))
      end)

    %{s | readers: readers}
  end

  defp add_node(s, node, key) do
    case s.nodes do
      %{^node => {ref, keys}} ->
        %{s | nodes: Map.put(s.nodes, node, {ref, MapSet.put(keys, key)})}

      _ ->
        %{s | nodes: Map.put(s.nodes, node, {Process.monitor(node), MapSet.new([key])})}
    end
  end

  defp ensure_tick(%{tick: nil, watched: watched} = s) when map_size(watched) > 0 do
    token = make_ref()
    ref = s.ctx.clock.send_after(self(), {:tick, token}, s.ctx.tick_ms)
    %{s | tick: {ref, token}}
  end

  defp ensure_tick(s), do: s
end
