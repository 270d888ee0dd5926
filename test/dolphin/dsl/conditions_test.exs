defmodule Dolphin.DSL.ConditionsTest do
  # A condition's expression reads its snapshot (Dolphin.Engine.Snapshot):
  # the macros rewrite its readers; what they cannot see into is followed
  # on the vehicles its task flies.
  use Dolphin.EngineCase, async: false

  # The script words, not the engine's functions of the same names.
  import Dolphin.Engine, only: []
  import Dolphin.DSL

  alias Dolphin.Engine.{Cond, Context, Snapshot}

  defp until_cond(%Dolphin.Engine.Until{cond: c}), do: c

  # A run whose clock ticks too rarely to matter: only events re-evaluate.
  setup do
    Context.put(%{Context.current() | tick_ms: 3_600_000})
    :ok
  end

  defp start_until(v, task_of_until) do
    t = Dolphin.Engine.on(task_of_until, [v])
    {:ok, run} = Dolphin.Engine.start(t)
    Dolphin.Test.Wait.until(fn -> Enum.any?(Dolphin.Engine.tasks(), &(&1.name == "survey")) end)
    run
  end

  defp survey, do: FakePlatform.task("survey", duration: :infinity)

  test "the readers of a condition's expression read the snapshot; nothing else is followed", ctx do
    [v] = fake_vehicles(ctx, 1, pick: true, battery: 0.9)
    c = until_cond(until(survey(), battery(v) < 0.3 and Enum.all?([v], fn x -> connected?(x) end)))
    assert %Cond{follow: false, source: "battery(v) < 0.3 and Enum.all?([v], fn x -> connected?(x) end)"} = c
    assert Cond.evaluate(c, %Snapshot{}) == {:read, {:vehicle, v}}
    assert Cond.evaluate(c) == {:ok, false}
    assert %Cond{follow: false} = until_cond(until(survey(), position(v).h > 100 or :math.sqrt(battery(v)) < 0.5))
    mod = Dolphin.DSL
    assert %Cond{follow: true} = until_cond(until(survey(), mod.battery(v) < 0.3))

    run = start_until(v, until(survey(), battery(v) < 0.3))
    FakeSource.set(ctx.source, v, battery: 0.2)
    assert {:ok, :done} = Dolphin.Engine.await(run, 5_000)
  end

  test "a condition through a script's own function reads live and is followed on its task's vehicles", ctx do
    [v] = fake_vehicles(ctx, 1, pick: true, battery: 0.9)
    low = fn v -> battery(v) < 0.3 end
    assert %Cond{follow: true} = until_cond(until(survey(), low.(v)))

    run = start_until(v, until(survey(), low.(v)))
    FakeSource.set(ctx.source, v, battery: 0.2)
    assert {:ok, :done} = Dolphin.Engine.await(run, 5_000)
  end

  test "a function that returns condition(...) is read through the snapshot", ctx do
    [v, other] = fake_vehicles(ctx, 2, pick: true, battery: 0.9)
    low = fn v -> condition(battery(v) < 0.3) end

    # The until's task flies `other`; the condition reads `v`, found by its request.
    run = start_until(other, until(survey(), low.(v)))
    FakeSource.set(ctx.source, v, battery: 0.2)
    assert {:ok, :done} = Dolphin.Engine.await(run, 5_000)
  end
end
