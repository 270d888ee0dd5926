defmodule Dolphin.Engine.ReassignTest do
  # reassign on fake vehicles (the fake platform); missions on the simulator
  # are in test/dolphin/mission/reassign_test.exs. The fleet and the engine's
  # registry are shared: not async.
  use Dolphin.EngineCase, async: false

  import Dolphin.DSL, only: [|||: 2]

  defp tp(name, opts \\ []), do: FakePlatform.task(name, Keyword.put_new(opts, :notify, self()))

  test "a lost vehicle's task goes to another picked vehicle, with a task_reassigned event", ctx do
    [a, b] = fake_vehicles(ctx, 2, pick: true)
    {:ok, run} = start(reassign(tp("survey", duration: :infinity, progress: [{0, %{reached: 3}}])))
    %{vehicle: first, task_id: id} = assert_platform(:started, "survey")
    other = if first == a, do: b, else: a
    await_event(run, &match?(%{event: :task_progress, progress: %{reached: 3}}, &1))
    FakeSource.lose(ctx.source, first)

    assert %{vehicle: ^other} = assert_platform(:started, "survey")
    e = await_event(run, &(&1.event == :task_reassigned))
    assert %{task_id: ^id, from: ^first, to: ^other, resume_seq: 3} = e
    assert :ok = stop(run)
    assert {:ok, :stopped} = await(run, 5_000)
  end

  test "the watch ends as the task taken over does", ctx do
    fake_vehicles(ctx, 2, pick: true)
    {:ok, run} = start(reassign(tp("patrol", duration: :infinity)))
    %{vehicle: first} = assert_platform(:started, "patrol")
    FakeSource.lose(ctx.source, first)
    %{vehicle: second, task_id: id} = assert_platform(:started, "patrol")
    assert second != first
    # Stopped from outside, the task taken over counts as completed: so does the watch.
    assert :ok = stop_task(id)
    assert {:ok, :done} = await(run, 5_000)
  end

  test "a vehicle fault (a failsafe) is taken over; any other failure is propagated unchanged", ctx do
    [_, _] = fake_vehicles(ctx, 2, pick: true)
    failsafe = tp("hot", duration: 1, result: {:fail, {:vehicle_fault, "battery failsafe"}})
    # Every vehicle fails it in turn: then no vehicle is left, and both reasons are said.
    assert {{:error, %Failure{reason: {:not_reassigned, {:vehicle_fault, "battery failsafe"}, why}} = f}, events} = run_events(reassign(failsafe))
    assert {:no_vehicle, nil, _requirements} = why
    assert Failure.format_reason(why) =~ "no vehicle among the vehicles the script picked"
    assert Failure.message(f) =~ "battery failsafe; no other vehicle could take it over"
    assert [%{from: v1, to: v2}] = Enum.filter(events, &(&1.event == :task_reassigned))
    assert v1 != v2

    assert {:error, %Failure{name: "gps", reason: :gps}} = run(reassign(FakePlatform.task("gps", duration: 1, result: {:fail, :gps})))
    refute_received {:dolphin, :events, %{event: :task_reassigned}}
  end

  test "from: limits the vehicles; a vehicle busy with another task of the run is not taken", ctx do
    [a, b, c] = fake_vehicles(ctx, 3, pick: true)
    t = reassign(on(tp("north", duration: :infinity), [a]), from: [a, b]) ||| on(tp("south", duration: :infinity), [b])
    {:ok, run} = start(t)
    assert_platform(:started, "north")
    assert_platform(:started, "south")
    FakeSource.lose(ctx.source, a)
    # b runs "south" and c is not in from: nobody can take "north" over.
    assert {:error, %Failure{name: "north", reason: {:not_reassigned, {:vehicle_lost, ^a}, why}}} = await(run, 5_000)
    assert {:no_vehicle, %VehicleSet{}, _} = why
    assert Failure.format_reason(why) =~ "among #{VehicleSet.format(VehicleSet.new([a, b]))}"

    [d, e] = fake_vehicles(ctx, 2, pick: true)
    {:ok, run} = start(reassign(on(tp("west", duration: :infinity), [d]), from: [d, c]) ||| on(tp("east", duration: :infinity), [e]))
    assert %{vehicle: ^d} = assert_platform(:started, "west")
    assert_platform(:started, "east")
    FakeSource.lose(ctx.source, d)
    assert %{vehicle: ^c} = assert_platform(:started, "west")
    assert :ok = stop(run)
    assert {:ok, :stopped} = await(run, 5_000)
  end

  test "reassign reads as written and refuses bad options" do
    assert inspect(reassign(idle(1))) == "#Task<reassign(idle(1))>"
    assert inspect(reassign(tp("t"), from: [1, 2])) =~ "reassign(\"t\", from: "
    assert_raise ArgumentError, ~r/from:/, fn -> reassign(idle(1), to: [1]) end
    assert_raise ArgumentError, ~r/from: goes with on_error: :reassign/, fn -> watch(idle(1), from: [1]) end
  end
end
