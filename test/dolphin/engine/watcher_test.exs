defmodule Dolphin.Engine.WatcherTest do
  use Dolphin.EngineCase, async: false

  alias Dolphin.Engine.{Cond, Signals, Snapshot, Watcher}
  alias Dolphin.Vehicles.View

  defp topics, do: Registry.keys(Dolphin.PubSub, self()) |> Enum.filter(&match?({t, _} when t in [:vehicle, :dolphin_signals], &1)) |> Enum.sort()

  test "a condition gets its snapshot as its argument; what it reads is followed, and let go when it is forgotten", ctx do
    [a, b] = fake_vehicles(ctx, 2, battery: 0.9)
    use_b = :atomics.new(1, [])
    reads = Cond.new(fn snap -> Snapshot.battery(snap, if(:atomics.get(use_b, 1) == 1, do: b, else: a)) < 0.3 end)

    w = Watcher.new(FakeSource.source(ctx.source))
    assert {{:ok, false}, w} = Watcher.evaluate(w, :low, reads)
    assert topics() == [{:vehicle, a}]
    assert Map.keys(w.vehicles) == [a]
    assert Watcher.reads?(w, :low, {:vehicle, a})

    # A change of what it read comes as a whole view, and the next evaluation reads it.
    FakeSource.set(ctx.source, a, battery: 0.2)
    assert_receive {:dolphin, {:vehicle, ^a}, {:view, %View{battery: 0.2} = view}}, 5_000
    w = Watcher.update(w, view)
    # The snapshot is what it reads: the source is not asked again.
    :ets.insert(ctx.source, {a, %{view | battery: 0.9}})
    assert {{:ok, true}, w} = Watcher.evaluate(w, :low, reads)

    # It reads another vehicle now: followed too, while the condition is watched.
    :atomics.put(use_b, 1, 1)
    assert {{:ok, false}, w} = Watcher.evaluate(w, :low, reads)
    assert topics() == Enum.sort([{:vehicle, a}, {:vehicle, b}])

    # Views of vehicles not followed are ignored; forgetting the condition lets everything go.
    assert Watcher.update(w, %{view | id: 1}).vehicles == w.vehicles
    assert %Watcher{vehicles: %{}} = Watcher.forget(w, :low)
    assert topics() == []
  end

  test "a snapshot's reader asks for what is not in it; with no snapshot, readers read live", ctx do
    [a] = fake_vehicles(ctx, 1, battery: 0.5)
    assert catch_throw(Snapshot.battery(%Snapshot{}, a)) == {:"$dolphin_read", {:vehicle, a}}
    assert Snapshot.battery(nil, a) == 0.5
    assert Cond.evaluate(Cond.new(fn snap -> Snapshot.battery(snap, a) end), %Snapshot{}) == {:read, {:vehicle, a}}
    assert Cond.evaluate(Cond.new(fn snap -> Snapshot.battery(snap, a) > 0.4 end)) == {:ok, true}
    # A condition of no argument reads live, and is followed on its task's vehicles.
    assert %Cond{follow: true} = Cond.new(fn -> true end)
    assert %Cond{follow: false} = Cond.new(fn _ -> true end)
  end

  test "signals read by a condition are followed; a followed vehicle stays whatever conditions read", ctx do
    [a] = fake_vehicles(ctx, 1)
    table = Signals.new()
    w = Watcher.new(FakeSource.source(ctx.source), table)
    assert {{:ok, %View{id: ^a}}, w} = Watcher.follow(w, a)

    assert {{:ok, false}, w} = Watcher.evaluate(w, :sig, Cond.new(fn snap -> Snapshot.poll(snap, :go) end))
    assert topics() == [{:dolphin_signals, table}, {:vehicle, a}]
    Signals.post(table, :go, 1)
    assert {{:ok, true}, w} = Watcher.evaluate(w, :sig, Cond.new(fn snap -> Snapshot.poll(snap, :go) end))
    w = Watcher.forget(w, :sig)
    assert topics() == [{:vehicle, a}]
    assert Map.keys(w.vehicles) == [a]
  end

  test "outside an evaluation, readers read live; unknown vehicles raise, or fail the condition" do
    assert_raise ArgumentError, ~r/unknown vehicle 77/, fn -> Watcher.vehicle(77) end
    w = Watcher.new(Dolphin.Engine.Context.current().source)
    assert {{:error, %ArgumentError{message: "unknown vehicle 77"}, _}, w} = Watcher.evaluate(w, :k, Cond.new(fn snap -> Snapshot.vehicle(snap, 77) end))
    assert w.vehicles == %{}
    assert topics() == []
  end
end
