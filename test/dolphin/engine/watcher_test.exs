defmodule Dolphin.Engine.WatcherTest do
  use Dolphin.EngineCase, async: false

  alias Dolphin.Engine.{Cond, Signals, Watcher}
  alias Dolphin.Vehicles.View

  defp topics, do: Registry.keys(Dolphin.PubSub, self()) |> Enum.filter(&match?({t, _} when t in [:vehicle_view, :dolphin_signals], &1)) |> Enum.sort()

  test "follows exactly the vehicles a condition read, and hands it their latest views", ctx do
    [a, b] = fake_vehicles(ctx, 2, battery: 0.9)
    use_b = :atomics.new(1, [])
    reads = Cond.new(fn -> Watcher.vehicle(if(:atomics.get(use_b, 1) == 1, do: b, else: a)).battery < 0.3 end)

    w = Watcher.new(TestSource.source(ctx.source))
    assert {{:ok, false}, w} = Watcher.evaluate(w, :low, reads)
    assert topics() == [{:vehicle_view, a}]
    assert Map.keys(w.vehicles) == [a]

    # A change of what it read comes as a whole view, and the next evaluation reads it.
    TestSource.set(ctx.source, a, battery: 0.2)
    assert_receive {:dolphin, {:vehicle_view, ^a}, {:view, %View{battery: 0.2} = view}}, 5_000
    w = Watcher.update(w, view)
    # The snapshot is what it reads: the source is not asked again.
    :ets.insert(ctx.source, {a, %{view | battery: 0.9}})
    assert {{:ok, true}, w} = Watcher.evaluate(w, :low, reads)

    # It reads another vehicle now: the first is let go.
    :atomics.put(use_b, 1, 1)
    assert {{:ok, false}, w} = Watcher.evaluate(w, :low, reads)
    assert topics() == [{:vehicle_view, b}]

    # Views of vehicles not followed are ignored; forgetting the condition lets everything go.
    assert Watcher.update(w, %{view | id: 1}).vehicles == w.vehicles
    assert %Watcher{vehicles: %{}} = Watcher.forget(w, :low)
    assert topics() == []
  end

  test "signals read by a condition are followed; a followed vehicle stays whatever conditions read", ctx do
    [a] = fake_vehicles(ctx, 1)
    table = Signals.new()
    w = Watcher.new(TestSource.source(ctx.source))
    assert {{:ok, %View{id: ^a}}, w} = Watcher.follow(w, a)

    assert {{:ok, false}, w} = Watcher.evaluate(w, :sig, Cond.new(fn -> Signals.poll(table, :go) end))
    assert topics() == [{:dolphin_signals, table}, {:vehicle_view, a}]
    w = Watcher.forget(w, :sig)
    assert topics() == [{:vehicle_view, a}]
    assert Map.keys(w.vehicles) == [a]
  end

  test "outside an evaluation, readers read live; unknown vehicles raise" do
    assert_raise ArgumentError, ~r/unknown vehicle 77/, fn -> Watcher.vehicle(77) end
    assert {{:error, %ArgumentError{}, _}, w} = Watcher.evaluate(Watcher.new(Dolphin.Engine.Context.current().source), :k, Cond.new(fn -> Watcher.vehicle(77) end))
    assert w.vehicles == %{}
    assert topics() == []
  end
end
