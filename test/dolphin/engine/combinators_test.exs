defmodule Dolphin.Engine.CombinatorsTest do
  # One process tree per run, the fleet's and platform's processes: not async.
  use Dolphin.EngineCase, async: false

  import Dolphin.DSL, only: [>>>: 2, |||: 2]

  alias Dolphin.Engine.Cond
  alias Dolphin.Fleet.AllocationError

  doctest Dolphin.Engine.Task
  doctest Dolphin.Engine.Cond
  doctest Dolphin.Engine.Signals
  doctest Dolphin.Engine.Failure
  doctest Dolphin.Events

  defp never, do: Cond.new(fn -> false end, source: "never")
  defp low_battery(v), do: Cond.new(fn snap -> Dolphin.Engine.Snapshot.battery(snap, v) < 0.3 end, source: "battery < 0.3")
  defp tp(name, opts \\ []), do: FakePlatform.task(name, Keyword.put_new(opts, :notify, self()))

  describe "leaves" do
    test "idle completes" do
      assert {{:ok, :done}, events} = run_events(idle(5, name: "i"))
      assert summary(events) == [{:started, "i"}, {:finished, "i", :done}]
    end

    test "an action runs once; an exception fails it, naming the task" do
      me = self()
      assert {:ok, :done} = run(action(fn -> send(me, :ran) end))
      assert_received :ran
      refute_received :ran

      assert {:error, %Failure{name: "boom", kind: :action, reason: {:exception, %RuntimeError{message: "bad"}, _}} = f} =
               run(action(fn -> raise "bad" end, name: "boom"))

      assert Failure.message(f) =~ ~s(action "boom")
      assert Failure.message(f) =~ "RuntimeError: bad"
      assert {:error, %Failure{reason: {:throw, :x}}} = run(action(fn -> throw(:x) end))
      assert {:error, %Failure{reason: {:exit, :gone}}} = run(action(fn -> exit(:gone) end))
    end

    test "a condition that holds at start completes at once; one that raises fails the task" do
      assert {{:ok, :done}, events} = run_events(condition(fn -> true end, name: "c"))
      assert [{:started, "c"}, {:met, _}, {:finished, "c", :done}] = summary(events)

      assert {:error, %Failure{reason: {:condition_error, "oops", %ArithmeticError{}}}} =
               run(condition(Cond.new(fn -> 1 / Process.get(:zero, 0) end, source: "oops")))
    end

    test "a condition is evaluated again when the vehicle it reads changes", ctx do
      [v] = fake_vehicles(ctx, 1)
      {:ok, run} = start(condition(low_battery(v), name: "low"))
      wait_running("low")
      FakeSource.set(ctx.source, v, battery: 0.5)
      FakeSource.set(ctx.source, v, battery: 0.2)
      assert {:ok, :done} = await(run, 5_000)
      assert [{:started, "low"}, {:met, _}, {:finished, "low", :done}] = summary(events_of(run))
    end
  end

  describe "sequence" do
    test "runs in order; a failure stops the rest" do
      assert {{:ok, :done}, events} = run_events(sequence([idle(1, name: "a"), idle(1, name: "b")], name: "s"))
      assert summary(events) == [{:started, "s"}, {:started, "a"}, {:finished, "a", :done}, {:started, "b"}, {:finished, "b", :done}, {:finished, "s", :done}]

      t = sequence([action(fn -> raise "no" end, name: "bad"), idle(1, name: "never")])
      assert {{:error, %Failure{name: "bad"}}, events} = run_events(t)
      refute {:started, "never"} in summary(events)
    end

    test "t1 >>> t2 >>> t3 is one sequence" do
      assert %Dolphin.Engine.Sequence{tasks: [_, _, _]} = idle(1) >>> idle(2) >>> idle(3)
    end
  end

  describe "concurrent" do
    test "completes when all have" do
      t = concurrent([idle(5, name: "a"), idle(1, name: "b")], name: "c")
      assert {{:ok, :done}, events} = run_events(t)
      s = summary(events)
      assert List.last(s) == {:finished, "c", :done}
      assert {:finished, "a", :done} in s and {:finished, "b", :done} in s
    end

    test "a failure stops the others, down to their platform tasks, and fails the whole", ctx do
      fake_vehicles(ctx, 2, pick: true)

      t =
        concurrent([
          idle(10) >>> action(fn -> raise "engine fire" end, name: "fire"),
          sequence([idle(1), until(concurrent([tp("left", duration: :infinity), tp("right", duration: :infinity)]), never())])
        ])

      assert {{:error, %Failure{name: "fire"} = f}, events} = run_events(t)
      assert f.reason |> elem(1) |> Map.get(:message) == "engine fire"
      # Both platform tasks got their stop callback before the run returned.
      assert_received {:fake_platform, :stopped, %{name: "left", reason: {:sibling_failed, 0}}}
      assert_received {:fake_platform, :stopped, %{name: "right", reason: {:sibling_failed, 0}}}
      assert {:finished, "left", :stopped} in summary(events)
      assert {:finished, "right", :stopped} in summary(events)
    end

    test "concurrent platform tasks run on distinct vehicles", ctx do
      ids = fake_vehicles(ctx, 2, pick: true)
      {:ok, :done} = run(tp("a", duration: 1) ||| tp("b", duration: 1))
      a = assert_platform(:started, "a")
      b = assert_platform(:started, "b")
      assert Enum.sort([a.vehicle, b.vehicle]) == Enum.sort(ids)
    end
  end

  describe "until" do
    test "stops its task when the condition holds, with the platform's stop callback", ctx do
      [v] = fake_vehicles(ctx, 1, pick: true)
      {:ok, run} = start(until(tp("survey", duration: :infinity), low_battery(v), name: "u") >>> idle(1, name: "after"))
      assert_platform(:started, "survey")
      FakeSource.set(ctx.source, v, battery: 0.1)
      assert {:ok, :done} = await(run, 5_000)
      assert %{reason: {:condition_met, _}} = assert_platform(:stopped, "survey")

      assert [{:started, _}, {:started, "u"}, {:started, "survey"}, {:met, _}, {:finished, "survey", :stopped}, {:finished, "u", :done}, {:started, "after"} | _] =
               summary(events_of(run))
    end

    test "completes with its task; a condition true at start means the task never starts", ctx do
      [v] = fake_vehicles(ctx, 1, pick: true)
      assert {:ok, :done} = run(until(tp("quick", duration: 1), never()))
      assert_platform(:finished, "quick")
      FakeSource.set(ctx.source, v, battery: 0.1)
      assert {{:ok, :done}, events} = run_events(until(tp("skipped"), low_battery(v)))
      refute {:started, "skipped"} in summary(events)
    end

    test "a failure of its task fails it", ctx do
      fake_vehicles(ctx, 1, pick: true)
      assert {:error, %Failure{name: "broken", reason: :motor}} = run(until(tp("broken", duration: 1, result: {:fail, :motor}), never()))
    end
  end

  describe "during" do
    test "stops its task after the time, and completes" do
      assert {{:ok, :done}, events} = run_events(during(10, idle(60_000, name: "long"), name: "d"))
      assert summary(events) == [{:started, "d"}, {:started, "long"}, {:finished, "long", :stopped}, {:finished, "d", :done}]
    end

    test "completes when its task does" do
      assert {{:ok, :done}, events} = run_events(during(60_000, idle(1, name: "short"), name: "d"))
      assert summary(events) == [{:started, "d"}, {:started, "short"}, {:finished, "short", :done}, {:finished, "d", :done}]
    end
  end

  describe "wait_for" do
    test "waits, then runs its task", ctx do
      [v] = fake_vehicles(ctx, 1)
      {:ok, run} = start(wait_for(low_battery(v), idle(1, name: "then"), name: "w"))
      wait_running("w")
      FakeSource.set(ctx.source, v, battery: 0.2)
      assert {:ok, :done} = await(run, 5_000)
      assert [{:started, "w"}, {:met, _}, {:started, "then"}, {:finished, "then", :done}, {:finished, "w", :done}] = summary(events_of(run))
    end
  end

  describe "one_of" do
    test "the first branch whose condition holds runs; the others are dropped", ctx do
      [a, b] = fake_vehicles(ctx, 2)
      t = one_of([{low_battery(a), idle(1, name: "A")}, {low_battery(b), idle(1, name: "B")}], name: "o")
      {:ok, run} = start(t)
      wait_running("o")
      FakeSource.set(ctx.source, b, battery: 0.1)
      assert {:ok, :done} = await(run, 5_000)
      events = events_of(run)
      assert [%{branch: 1}] = Enum.filter(events, &(&1.event == :condition_met))
      assert {:finished, "B", :done} in summary(events)
      refute {:started, "A"} in summary(events)
      # A's condition holding later changes nothing.
      FakeSource.set(ctx.source, a, battery: 0.1)
    end

    test "at start, the earliest branch that holds wins" do
      t = one_of([{fn -> false end, idle(1, name: "A")}, {fn -> true end, idle(1, name: "B")}, {fn -> true end, idle(1, name: "C")}])
      assert {{:ok, :done}, events} = run_events(t)
      assert {:started, "B"} in summary(events)
      refute {:started, "C"} in summary(events)
    end
  end

  describe "all_of" do
    test "every branch runs when its condition holds; completes when all have", ctx do
      [a, b] = fake_vehicles(ctx, 2)
      t = all_of([{low_battery(a), idle(1, name: "A")}, {low_battery(b), idle(1, name: "B")}], name: "all")
      {:ok, run} = start(t)
      wait_running("all")
      FakeSource.set(ctx.source, b, battery: 0.1)
      await_event(run, &match?(%{event: :task_finished, name: "B"}, &1))
      assert {:error, :timeout} = await(run, 0)
      FakeSource.set(ctx.source, a, battery: 0.1)
      assert {:ok, :done} = await(run, 5_000)
      assert [{:started, "all"}, {:met, _}, {:started, "B"}, {:finished, "B", :done}, {:met, _}, {:started, "A"}, {:finished, "A", :done}, {:finished, "all", :done}] =
               summary(events_of(run))
    end

    test "a failed branch stops the running ones and drops the waiting ones", ctx do
      fake_vehicles(ctx, 1, pick: true)

      t =
        all_of([
          {fn -> true end, tp("runs", duration: :infinity)},
          {fn -> true end, idle(5) >>> action(fn -> raise "x" end, name: "bad")},
          {fn -> false end, idle(1, name: "waits")}
        ])

      assert {{:error, %Failure{name: "bad"}}, events} = run_events(t)
      assert_received {:fake_platform, :stopped, %{name: "runs"}}
      refute {:started, "waits"} in summary(events)
    end
  end

  describe "watch" do
    test ":ignore, :propagate" do
      bad = action(fn -> raise "x" end, name: "bad")
      assert {:ok, :done} = run(watch(bad, on_error: :ignore))
      assert {:error, %Failure{name: "bad"}} = run(watch(bad, on_error: :propagate))
      assert {:error, %Failure{name: "bad"}} = run(watch(bad))
    end

    test "a handler is given the failure; a task it returns runs", ctx do
      fake_vehicles(ctx, 1, pick: true)
      me = self()

      recover = tp("recover", duration: 1)

      handler = fn %Failure{} = f ->
        send(me, {:handled, f.name, f.vehicle})
        recover
      end

      assert {{:ok, :done}, events} = run_events(watch(tp("flaky", duration: 1, result: {:fail, :gps}), on_error: handler))
      assert_received {:handled, "flaky", v} when is_integer(v)
      # The recovery runs on the vehicle the failed task had.
      assert %{vehicle: ^v} = assert_platform(:started, "recover")
      assert {:finished, "recover", :done} in summary(events)
    end

    test "a handler returning anything else completes the watch; one that raises fails it" do
      bad = action(fn -> raise "x" end)
      assert {:ok, :done} = run(watch(bad, on_error: fn _ -> :ok end))
      assert {:error, %Failure{reason: {:handler_failed, {:exception, %RuntimeError{message: "worse"}, _}}}} = run(watch(bad, on_error: fn _ -> raise "worse" end))
    end
  end

  describe "platform tasks" do
    test "a lost vehicle fails the task running on it", ctx do
      [v] = fake_vehicles(ctx, 1, pick: true)
      {:ok, run} = start(tp("far", duration: :infinity))
      assert_platform(:started, "far")
      FakeSource.lose(ctx.source, v)
      assert {:error, %Failure{name: "far", vehicle: ^v, reason: {:vehicle_lost, ^v}} = f} = await(run, 5_000)
      assert Failure.message(f) =~ "vehicle #{v} lost"
      assert %{reason: {:vehicle_lost, ^v}} = assert_platform(:stopped, "far")
    end

    test "the stop callback is waited for before the subtree is gone", ctx do
      fake_vehicles(ctx, 1, pick: true)
      {:ok, run} = start(during(5, tp("holds", duration: :infinity, stop_ms: 100)))
      assert {:ok, :done} = await(run, 5_000)
      %{pid: pid} = assert_received_stop("holds")
      refute Process.alive?(pid)
    end

    test "a stop that does not return in time kills the task and fails", ctx do
      fake_vehicles(ctx, 1, pick: true)
      t = during(5, tp("stuck", duration: :infinity, stop_ms: 10_000_000))
      assert {:error, %Failure{name: "stuck", reason: {:stop_timeout, 50}}} = run(t, stop_timeout_ms: 50)
    end

    test "a stop the platform refuses fails the task, whether it is sent as a request or called in a helper", ctx do
      fake_vehicles(ctx, 1, pick: true)

      for task <- [tp("refuses", duration: :infinity, stop_result: {:error, "no hold"}), by_callback(tp("refuses", duration: :infinity, stop_result: {:error, "no hold"}))] do
        assert {:error, %Failure{name: "refuses", reason: {:stop_failed, "no hold"}} = f} = run(during(5, task))
        assert Failure.message(f) =~ "could not be stopped: no hold"
        assert_received_stop("refuses")
      end
    end

    test "a platform without stop_request/1 is stopped through stop/2 in a helper: waited for, and bounded", ctx do
      fake_vehicles(ctx, 1, pick: true)
      assert {:ok, :done} = run(during(5, by_callback(tp("holds", duration: :infinity, stop_ms: 100))))
      %{pid: pid} = assert_received_stop("holds")
      refute Process.alive?(pid)

      t = during(5, by_callback(tp("stuck", duration: :infinity, stop_ms: 10_000_000)))
      assert {:error, %Failure{name: "stuck", reason: {:stop_timeout, 50}}} = run(t, stop_timeout_ms: 50)
      %{pid: pid} = assert_received_stop("stuck")
      refute Process.alive?(pid)
    end

    test "a platform process that exits without reporting fails its task", ctx do
      fake_vehicles(ctx, 1, pick: true)
      {:ok, run} = start(tp("dies", duration: :infinity))
      %{pid: pid} = assert_platform(:started, "dies")
      Process.exit(pid, :kill)
      assert {:error, %Failure{name: "dies", reason: {:platform_exited, :killed}}} = await(run, 5_000)
    end

    test "no allocation: the error names the task", ctx do
      fake_vehicles(ctx, 1, pick: true, type: :uav)
      assert {:error, %AllocationError{task_name: "boat"} = e} = run(tp("boat", type: :usv))
      assert Exception.message(e) =~ "type :usv"
      assert {:error, %AllocationError{task_name: "b"}} = run(tp("a") ||| tp("b"))
    end
  end

  describe "stopping" do
    test "stopping a run stops every platform task and reports stopped", ctx do
      fake_vehicles(ctx, 2, pick: true)
      {:ok, run} = start(tp("x", duration: :infinity) ||| (idle(1) >>> tp("y", duration: :infinity)))
      assert_platform(:started, "y")
      :ok = Dolphin.Engine.stop(run)
      assert {:ok, :stopped} = await(run, 5_000)
      assert_received_stop("x")
      assert_received_stop("y")
    end

    test "when the caller dies, its run stops its platform tasks", ctx do
      fake_vehicles(ctx, 1, pick: true)
      me = self()
      ctx_ = Dolphin.Engine.Context.current()
      orphan = tp("orphan", duration: :infinity)

      caller =
        spawn(fn ->
          Dolphin.Engine.Context.put(%{ctx_ | owner: me})
          Dolphin.Engine.run(orphan)
        end)

      assert_platform(:started, "orphan")
      Process.exit(caller, :kill)
      assert %{reason: {:parent_exit, :killed}} = assert_platform(:stopped, "orphan")
    end

    test "killing a node still stops the platform tasks under it", ctx do
      fake_vehicles(ctx, 1, pick: true)
      {:ok, run} = start(sequence([until(tp("deep", duration: :infinity), never(), name: "u")]))
      assert_platform(:started, "deep")
      [%{pid: pid}] = Enum.filter(Dolphin.Engine.tasks(), &(&1.run == run and &1.name == "u"))
      Process.exit(pid, :kill)
      assert %{reason: {:parent_exit, :killed}} = assert_platform(:stopped, "deep")
      assert {:error, %Failure{name: "u", reason: {:crashed, :killed}}} = await(run, 5_000)
    end

    test "the operator stops one task; its parent goes on", ctx do
      fake_vehicles(ctx, 1, pick: true)
      {:ok, run} = start(tp("loiter", duration: :infinity) >>> idle(1, name: "next"))
      %{task_id: id} = assert_platform(:started, "loiter")
      :ok = Dolphin.Engine.stop_task(id)
      assert {:ok, :done} = await(run, 5_000)
      assert %{reason: :operator} = assert_platform(:stopped, "loiter")
      assert {:finished, "next", :done} in summary(events_of(run))
    end
  end

  defp wait_running(name), do: Dolphin.Test.Wait.until(fn -> Enum.any?(Dolphin.Engine.tasks(), &(&1.name == name)) end)

  # The fake platform's task as a platform that has no stop_request/1.
  defp by_callback(fake), do: Dolphin.Engine.platform_task(Dolphin.Engine.CombinatorsTest.CallbackStop, fake)

  defp assert_received_stop(name) do
    assert_receive {:fake_platform, :stopped, %{name: ^name} = info}, 5_000
    info
  end
end

defmodule Dolphin.Engine.CombinatorsTest.CallbackStop do
  @moduledoc false
  # The fake platform without stop_request/1: the engine stops its tasks by
  # calling stop/2 in a helper process.
  @behaviour Dolphin.Engine.Platform

  alias Dolphin.Engine.FakePlatform

  @impl true
  defdelegate name(spec), to: FakePlatform
  @impl true
  defdelegate kind(spec), to: FakePlatform
  @impl true
  defdelegate requirements(spec), to: FakePlatform
  @impl true
  defdelegate start(spec, vehicle, opts), to: FakePlatform
  @impl true
  defdelegate stop(pid, reason), to: FakePlatform
end
