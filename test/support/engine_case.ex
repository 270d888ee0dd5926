defmodule Dolphin.EngineCase do
  @moduledoc """
  Tests of the engine, the fleet and scripts: each test gets its own fake
  vehicle source and fleet (events off), set as the test process's
  `Dolphin.Engine.Context`, and is subscribed to `Dolphin.Events` events.

      test "...", ctx do
        [v] = fake_vehicles(ctx, 1, pick: true)
        {result, events} = run_events(idle(10))
      end

  Vehicle ids are fresh for each test (pub/sub topics are shared).
  """

  use ExUnit.CaseTemplate

  alias Dolphin.Engine.Context
  alias Dolphin.Fleet.FakeSource

  using do
    quote do
      import Dolphin.Engine
      import Dolphin.EngineCase
      alias Dolphin.Engine.{Failure, FakePlatform}
      alias Dolphin.Fleet.{FakeSource, VehicleSet}
    end
  end

  setup do
    n = System.unique_integer([:positive])
    source = :"fakes_#{n}"
    fleet = :"fleet_#{n}"
    start_supervised!({FakeSource, name: source, events: false})
    start_supervised!({Dolphin.Fleet, name: fleet, source: FakeSource.source(source), events: false})
    Context.put(%Context{fleet: fleet, source: FakeSource.source(source), owner: self()})
    Dolphin.Events.subscribe()
    {:ok, source: source, fleet: fleet}
  end

  @doc "Adds `n` fake vehicles with fresh ids and `attrs`; `pick: true` picks them for the test process. Returns the ids."
  def fake_vehicles(ctx, n, attrs \\ []) do
    {pick, attrs} = Keyword.pop(attrs, :pick, false)
    ids = for _ <- 1..n, do: 100_000 + System.unique_integer([:positive, :monotonic])
    Enum.each(ids, &FakeSource.add(ctx.source, &1, attrs))
    # The fleet has seen them once it answers (the discoveries are ahead in its mailbox).
    _ = Dolphin.Fleet.vehicles(ctx.fleet)
    if pick, do: {:ok, _} = Dolphin.Fleet.pick(ctx.fleet, self(), id: ids, count: n, timeout: 5_000)
    ids
  end

  @doc "Runs a task; returns its result and the events of its run, in order."
  def run_events(task, opts \\ []) do
    {:ok, run} = Dolphin.Engine.start(task, opts)
    result = Dolphin.Engine.await(run, 30_000)
    {result, events_of(run)}
  end

  @doc "The events of a run that has ended: up to its root's task_finished, then whatever is already queued."
  def events_of(run) do
    collect(run, Enum.reverse(Process.delete({:seen_events, run}) || []))
  end

  @doc """
  Waits (bounded) for an event of a run matching `fun`, and returns it; the
  events received on the way are kept for `events_of/1`.
  """
  def await_event(run, fun, timeout \\ 5_000) do
    receive do
      {:dolphin, :events, %{run: ^run} = e} ->
        Process.put({:seen_events, run}, (Process.get({:seen_events, run}) || []) ++ [e])
        if fun.(e), do: e, else: await_event(run, fun, timeout)
    after
      timeout -> ExUnit.Assertions.flunk("no such event of run #{run}")
    end
  end

  defp collect(run, acc) do
    receive do
      {:dolphin, :events, %{run: ^run, event: :task_finished, parent_id: nil} = e} -> drain(run, [e | acc])
      {:dolphin, :events, %{run: ^run} = e} -> collect(run, [e | acc])
    after
      5_000 -> Enum.reverse(acc)
    end
  end

  defp drain(run, acc) do
    receive do
      {:dolphin, :events, %{run: ^run} = e} -> drain(run, [e | acc])
    after
      0 -> Enum.reverse(acc)
    end
  end

  @doc "Events as compact tuples: `{:started | :finished | :met, name}` (+ result for finished)."
  def summary(events) do
    Enum.flat_map(events, fn
      %{event: :task_started, name: n} -> [{:started, n}]
      %{event: :task_finished, name: n, result: r} -> [{:finished, n, r}]
      %{event: :condition_met, task_id: id} -> [{:met, id}]
      _ -> []
    end)
  end

  @doc "Receives the next fake platform notification of `event` for `name` (bounded)."
  defmacro assert_platform(event, name, timeout \\ 5_000) do
    quote do
      assert_receive {:fake_platform, unquote(event), %{name: unquote(name)} = info}, unquote(timeout)
      info
    end
  end
end
