defmodule Dolphin.Engine.SysTest do
  # A running task tree's processes answer OTP's system messages, so that
  # :sys and observer can look into any of them.
  use Dolphin.EngineCase, async: false

  alias Dolphin.Engine.Cond

  defp tp(name, opts \\ []), do: FakePlatform.task(name, Keyword.merge([notify: self(), duration: :infinity], opts))

  # The processes under a run, found by walking the states :sys.get_state/1
  # returns: the run's root node, each node's children and platform task.
  defp walk(pid, depth) do
    state = :sys.get_state(pid, 5_000)

    below =
      case state do
        %{root: root} -> [root]
        %{children: children, platform: platform} -> Enum.map(Map.values(children), & &1.pid) ++ List.wrap(platform)
        _platform_task -> []
      end

    [{depth, pid, state} | Enum.flat_map(below, &walk(&1, depth + 1))]
  end

  test ":sys.get_state/1 answers on every process of a running task tree", ctx do
    [a, b] = fake_vehicles(ctx, 2, pick: true)
    low = Cond.new(fn snap -> Dolphin.Engine.Snapshot.battery(snap, a) < 0.3 end, source: "battery(a) < 0.3")
    tree = sequence([idle(0, name: "warm-up"), until(concurrent([tp("survey"), tp("photos")]), low, name: "until low"), idle(0, name: "after")], name: "main")

    {:ok, run} = start(tree)
    assert_platform(:started, "survey")
    assert_platform(:started, "photos")
    [%{pid: run_pid}] = Enum.filter(runs(), &(&1.run == run))

    procs = walk(run_pid, 0)
    states = Enum.map(procs, fn {_depth, _pid, state} -> state end)

    # run -> sequence -> until -> concurrent -> two leaves -> their platform tasks
    assert length(procs) == 8
    assert %{run: %{id: ^run}} = hd(states)
    assert Enum.map(tl(states), &Map.get(&1, :kind)) == [:sequence, :until, :concurrent, :test, nil, :test, nil]
    assert Enum.sort(for %{kind: :test, vehicle: v} <- states, do: v) == Enum.sort([a, b])

    # The node processes are the ones the engine lists for the run (the
    # registry forgets the finished warm-up's node a moment after its exit).
    nodes = for {_, pid, %{kind: _}} <- procs, do: pid
    listed = fn -> Enum.sort(for %{run: ^run, pid: pid} <- tasks(), do: pid) end
    Dolphin.Test.Wait.until(fn -> Enum.sort(nodes) == listed.() end, 250, fn -> "#{inspect(Enum.sort(nodes))} == #{inspect(listed.())}" end)

    # The run's conditions process answers too: it watches the until's condition.
    [{_, until_pid, _}] = for {_, _, %{kind: :until}} = p <- procs, do: p
    %{watched: watched} = :sys.get_state(hd(states).run.conditions, 5_000)
    assert [{^until_pid, :c}] = Map.keys(watched)

    # Debug hooks see the messages a node handles: the until node is told its condition holds.
    me = self()
    :ok = :sys.install(until_pid, {fn acc, event, _name -> send(me, {:sys_event, event}) && acc end, nil})
    FakeSource.set(ctx.source, a, battery: 0.2)
    assert_receive {:sys_event, {:in, {:"$dolphin_condition", :c}}}, 5_000
    assert {:ok, :done} = await(run, 10_000)
  end

  test "a node waiting for its parent's report answers system messages", ctx do
    [a] = fake_vehicles(ctx, 1, pick: true)
    {:ok, run} = start(sequence([tp("long", stop_ms: 0)], name: "seq"))
    assert_platform(:started, "long")
    [%{pid: run_pid}] = Enum.filter(runs(), &(&1.run == run))
    %{root: root} = :sys.get_state(run_pid)
    %{children: children} = :sys.get_state(root)
    [%{pid: leaf}] = Map.values(children)

    # Phase 1 only: the leaf stops its platform task and waits for the report.
    send(leaf, {:"$dolphin_stop", :operator})
    assert_platform(:stopped, "long")
    assert %{kind: :test, vehicle: ^a, platform: nil} = :sys.get_state(leaf)
    assert :ok = Dolphin.Engine.stop(run)
    assert {:ok, :stopped} = await(run, 10_000)
  end
end
