defmodule Dolphin.DSL.UnknownTest do
  # A condition that depends on a value nobody has seen yet (nil) is not met,
  # and reading one never raises (Dolphin.DSL, "Unknown values").
  use Dolphin.EngineCase, async: false

  # The script words, not the engine's functions of the same names.
  import Dolphin.Engine, only: []
  import Dolphin.DSL
  import Dolphin.DSL.Values

  alias Dolphin.Engine.{Cond, Context}

  @ops [:<, :<=, :>, :>=, :==, :!=, :===, :!==]

  # reader => {the field a fake vehicle leaves unknown, a known value of the reader}
  @readers [
    battery: {:battery, 0.5},
    position: {:position, quote(do: location(41.0, -8.0, 0))},
    altitude: {:position, 100.0},
    relative_altitude: {:relative_altitude, 10.0},
    mode: {:mode, :guided},
    armed?: {:armed?, true},
    connected?: {:connected?, true},
    mission_progress: {:mission_progress, {1, 3}}
  ]

  # Evaluated on live data (no snapshot: the readers read the source), in a
  # process of the test's context.
  defp evaluate(%{cond: c}) do
    ctx = Context.current()
    Task.async(fn ->
      Context.put(ctx)
      Cond.evaluate(c)
    end)
    |> Task.await()
  end

  defp unknown_vehicle(ctx, field) do
    [v] = fake_vehicles(ctx, 1, [{field, nil}])
    VehicleSet.new(v)
  end

  for {reader, {field, known}} <- @readers do
    v = Macro.var(:v, nil)
    read = {reader, [], [v]}

    unmet =
      [read, quote(do: not unquote(read)), quote(do: !unquote(read))] ++
        Enum.flat_map(@ops, fn op ->
          cmp = {op, [], [read, known]}

          [
            cmp,
            {op, [], [known, read]},
            quote(do: not unquote(cmp)),
            quote(do: !unquote(cmp)),
            quote(do: unquote(cmp) and true),
            quote(do: true and unquote(cmp)),
            quote(do: unquote(cmp) && true),
            quote(do: unquote(cmp) or false),
            quote(do: false or unquote(cmp)),
            quote(do: unquote(cmp) || false),
            quote(do: not (unquote(cmp) and true)),
            quote(do: not (unquote(cmp) or false)),
            quote(do: unquote(cmp) == true),
            quote(do: unquote(cmp) != true),
            quote(do: unquote(read) != nil)
          ]
        end) ++
        [
          quote(do: unquote(read) in [unquote(known)]),
          quote(do: unquote(read) not in [unquote(known)]),
          quote(do: not (unquote(read) in [unquote(known), nil]))
        ]

    met = [
      quote(do: unquote({:<, [], [read, known]}) or true),
      quote(do: true || unquote({:>=, [], [read, known]})),
      quote(do: not (false and unquote({:>, [], [read, known]}))),
      quote(do: unquote(read) == nil),
      quote(do: is_nil(unquote(read)))
    ]

    test "#{reader}(v) unknown: no comparison, negation or combination of it holds; known parts still decide", ctx do
      v = unknown_vehicle(ctx, unquote(field))

      for {source, c} <- unquote(Enum.map(unmet, fn c -> quote(do: {unquote(Macro.to_string(c)), condition(unquote(c))}) end)) do
        assert evaluate(c) == {:ok, false}, "#{source} held (or raised) with #{unquote(reader)} unknown: #{inspect(evaluate(c))}"
      end

      for {source, c} <- unquote(Enum.map(met, fn c -> quote(do: {unquote(Macro.to_string(c)), condition(unquote(c))}) end)) do
        assert evaluate(c) == {:ok, true}, "#{source} did not hold with #{unquote(reader)} unknown: #{inspect(evaluate(c))}"
      end
    end
  end

  test "once reported, the same conditions are Elixir's comparisons", ctx do
    [id] = fake_vehicles(ctx, 1, battery: 0.95, mode: :guided, mission_progress: {2, 5}, armed?: false)
    v = VehicleSet.new(id)

    assert evaluate(condition(battery(v) >= 0.9)) == {:ok, true}
    assert evaluate(condition(not (battery(v) < 0.3))) == {:ok, true}
    assert evaluate(condition(battery(v) * 100 > 90 and mode(v) == :guided)) == {:ok, true}
    assert evaluate(condition(mission_progress(v) >= {2, 0} and not armed?(v))) == {:ok, true}
    assert evaluate(condition(mode(v) != :auto or battery(v) < 0.1)) == {:ok, true}
    assert evaluate(condition(position(v) != nil)) == {:ok, true}
    assert evaluate(condition(mode(v) == :auto)) == {:ok, false}
    assert evaluate(condition(mode(v) in [:guided, :auto] and mode(v) not in [:rtl])) == {:ok, true}

    FakeSource.set(ctx.source, id, battery: nil)
    assert evaluate(condition(battery(v) >= 0.9)) == {:ok, false}
    assert evaluate(condition(not (battery(v) >= 0.9))) == {:ok, false}
  end

  test "arithmetic and geometry on an unknown position or altitude are unknown, never an error", ctx do
    v = unknown_vehicle(ctx, :position)
    p = location(41.0, -8.0, 0)

    conds = [
      condition(distance(position(v), p) < 10),
      condition(distance(p, position(v)) >= 10),
      condition(not (distance(position(v), p) < 10)),
      condition(near?(position(v), p, 10)),
      condition(not near?(position(v), p, 10)),
      condition(contains?(area(p, 10), position(v))),
      condition(!contains?(area(p, 10), position(v))),
      condition(altitude(v) - 100 > 5),
      condition(-altitude(v) < 0),
      condition(altitude(v) * 2 / 3 + 1 <= 50),
      condition(relative_altitude(v) - altitude(v) > 0)
    ]

    for c <- conds, do: assert(evaluate(c) == {:ok, false}, "#{c.cond.source}: #{inspect(evaluate(c))}")
    assert distance(nil, p) == nil and near?(p, nil, 3) == nil and contains?(area(p, 10), nil) == nil
  end

  test "filter with a condition written in place leaves out vehicles whose value is unknown", ctx do
    [low, unknown, high] = for b <- [0.2, nil, 0.8], do: hd(fake_vehicles(ctx, 1, battery: b))
    set = VehicleSet.new([low, unknown, high])

    assert filter(set, fn x -> battery(x) > 0.5 end) == VehicleSet.new(high)
    assert filter(set, fn x -> not (battery(x) <= 0.5) end) == VehicleSet.new(high)
    assert filter(set, fn x -> battery(x) == nil end) == VehicleSet.new(unknown)
    # A function given by name is Elixir's, as written.
    keep = fn x -> battery(x) != nil end
    assert filter(set, keep) == VehicleSet.new([low, high])
  end

  test "one_of does not take a branch on an unknown battery; a wait_for on it ends once it is reported", ctx do
    [id] = fake_vehicles(ctx, 1, battery: nil)
    v = VehicleSet.new(id)

    task =
      one_of do
        battery(v) >= 0.9 -> action(do: :survey)
        mode(v) == nil -> action(do: :wait)
      end

    {{:ok, _}, events} = run_events(task)
    assert [%{branch: 1, condition: "mode(v) == nil"}] = for(%{event: :condition_met} = e <- events, do: e)

    run = Dolphin.Engine.start(wait_for(battery(v) >= 0.9, then: action(do: :survey)))
    assert {:ok, run} = run
    await_event(run, &match?(%{event: :task_started, kind: :wait_for}, &1))
    # A report that leaves the battery unknown, then the battery: the condition is read again on each.
    FakeSource.set(ctx.source, id, mode: :guided)
    FakeSource.set(ctx.source, id, battery: 0.95)
    met = await_event(run, &match?(%{event: :condition_met}, &1))
    assert {:ok, _} = Dolphin.Engine.await(run, 30_000)
    assert met.condition == "battery(v) >= 0.9"
  end
end
