defmodule Dolphin.Engine.ConditionsTest do
  # The run's conditions process (Dolphin.Engine.Conditions): it evaluates
  # the untils' conditions and sends the platforms under each that holds
  # their stop itself (Dolphin.Engine.Stops); the leaves await those answers.
  use Dolphin.EngineCase, async: false

  alias Dolphin.Engine.{Cond, Snapshot}

  defp tp(name, opts \\ []), do: FakePlatform.task(name, Keyword.merge([notify: self(), duration: :infinity], opts))
  defp low(v), do: Cond.new(fn snap -> Snapshot.battery(snap, v) < 0.3 end, source: "battery < 0.3")

  # A platform whose process ends, without answering, when it is asked to stop.
  defmodule Vanishing do
    use GenServer
    @behaviour Dolphin.Engine.Platform

    defstruct name: "vanishing", notify: nil

    @impl Dolphin.Engine.Platform
    def name(t), do: t.name
    @impl Dolphin.Engine.Platform
    def requirements(_t), do: %{}
    @impl Dolphin.Engine.Platform
    def start(t, _vehicle, opts), do: GenServer.start_link(__MODULE__, {t, opts[:owner]})
    @impl Dolphin.Engine.Platform
    def stop(pid, reason), do: GenServer.call(pid, stop_request(reason))
    @impl Dolphin.Engine.Platform
    def stop_request(reason), do: {:stop, reason}

    @impl GenServer
    def init({t, _owner}) do
      send(t.notify, {:vanishing, :started, self()})
      {:ok, t}
    end

    @impl GenServer
    def handle_call({:stop, reason}, _from, t) do
      send(t.notify, {:vanishing, :asked, reason})
      {:stop, :normal, t}
    end
  end

  defp hub_of(run) do
    [%{pid: run_pid}] = Enum.filter(runs(), &(&1.run == run))
    :sys.get_state(run_pid).run.conditions
  end

  test "a burst: every platform under the untils one change trips is stopped once, by its until's condition", ctx do
    n = 200
    [shared | vs] = fake_vehicles(ctx, n + 1, pick: true)
    tasks = for {v, i} <- Enum.with_index(vs), do: on(until(tp("t#{i}"), low(shared), name: "u#{i}"), [v])
    {:ok, run} = start(concurrent(tasks))
    for _ <- 1..n, do: assert_receive({:fake_platform, :started, _}, 5_000)

    FakeSource.set(ctx.source, shared, battery: 0.1)
    assert {:ok, :done} = await(run, 30_000)

    stops = for _ <- 1..n, do: assert_receive({:fake_platform, :stopped, info}, 5_000) && info
    refute_receive {:fake_platform, :stopped, _}, 200
    assert length(Enum.uniq_by(stops, & &1.task_id)) == n

    events = events_of(run)
    untils = for %{event: :task_started, kind: :until, task_id: id} <- events, do: id
    # Each platform's stop names the until right above it (its parent: ids are in pre-order).
    assert Enum.sort(for %{reason: {:condition_met, id}} <- stops, do: id) == Enum.sort(untils)
    assert Enum.sort(for(%{task_id: t} <- stops, do: t - 1)) == Enum.sort(untils)

    # One condition_met per until, before that until finishes, which it does done.
    met = for %{event: :condition_met, task_id: id} <- events, do: id
    assert Enum.sort(met) == Enum.sort(untils)

    for id <- untils do
      i_met = Enum.find_index(events, &match?(%{event: :condition_met, task_id: ^id}, &1))
      i_end = Enum.find_index(events, &match?(%{event: :task_finished, task_id: ^id}, &1))
      assert i_met < i_end
      assert %{result: :done} = Enum.at(events, i_end)
    end

    for %{event: :task_finished, kind: :test} = e <- events, do: assert(e.result == :stopped)
  end

  test "the platforms under an until are stopped while the until itself is busy (the stops do not wait for it)", ctx do
    [v, w1, w2] = fake_vehicles(ctx, 3, pick: true)
    {:ok, run} = start(until(concurrent([on(tp("a"), [w1]), on(tp("b"), [w2])]), low(v), name: "u"))
    assert_platform(:started, "a")
    assert_platform(:started, "b")
    [%{pid: until}] = Enum.filter(tasks(), &(&1.run == run and &1.name == "u"))

    :ok = :sys.suspend(until)
    FakeSource.set(ctx.source, v, battery: 0.1)
    assert %{reason: {:condition_met, _}} = assert_platform(:stopped, "a")
    assert %{reason: {:condition_met, _}} = assert_platform(:stopped, "b")
    :ok = :sys.resume(until)

    assert {:ok, :done} = await(run, 10_000)
    assert {:met, _} = List.keyfind(summary(events_of(run)), :met, 0)
  end

  test "nested untils tripped by one change stop their platform once", ctx do
    [v, w] = fake_vehicles(ctx, 2, pick: true)
    {:ok, run} = start(on(until(until(tp("inner task"), low(v), name: "inner"), low(v), name: "outer"), [w]))
    assert_platform(:started, "inner task")
    FakeSource.set(ctx.source, v, battery: 0.1)
    assert {:ok, :done} = await(run, 10_000)
    assert_platform(:stopped, "inner task")
    refute_receive {:fake_platform, :stopped, _}, 200
    assert [{:finished, "inner task", :stopped} | _] = for({:finished, _, _} = f <- summary(events_of(run)), do: f)
  end

  test "a platform that ends as its stop reaches it counts as stopped, not failed", ctx do
    [v, w] = fake_vehicles(ctx, 2, pick: true)
    task = platform_task(Vanishing, %Vanishing{notify: self()})
    {:ok, run} = start(sequence([on(until(task, low(v), name: "u"), [w]), idle(1, name: "after")]))
    assert_receive {:vanishing, :started, _}, 5_000
    FakeSource.set(ctx.source, v, battery: 0.1)
    assert {:ok, :done} = await(run, 10_000)
    assert_receive {:vanishing, :asked, {:condition_met, _}}
    refute_receive {:vanishing, :asked, _}, 200
    assert {:finished, "vanishing", :stopped} in summary(events_of(run))
  end

  test "a condition that raises while its task runs fails its until, as its node's own would", ctx do
    [v] = fake_vehicles(ctx, 1, pick: true)
    oops = Cond.new(fn snap -> if Snapshot.battery(snap, v) < 0.5, do: raise(ArithmeticError), else: false end, source: "oops")
    {:ok, run} = start(until(tp("survey"), oops))
    assert_platform(:started, "survey")
    FakeSource.set(ctx.source, v, battery: 0.4)
    assert {:error, %Failure{reason: {:condition_error, "oops", %ArithmeticError{}}}} = await(run, 10_000)
    assert_platform(:stopped, "survey")
  end

  test "what it watches: the untils' conditions, not those following their task's vehicles; it ends with its run", ctx do
    [v] = fake_vehicles(ctx, 1, pick: true)
    followed = Cond.new(fn -> false end, source: "live")
    {:ok, run} = start(until(until(tp("survey"), followed, name: "follows"), low(v), name: "reads"))
    assert_platform(:started, "survey")
    hub = hub_of(run)
    %{watched: watched} = :sys.get_state(hub)
    assert [%{cond: %{source: "battery < 0.3"}}] = Map.values(watched)

    ref = Process.monitor(hub)
    FakeSource.set(ctx.source, v, battery: 0.1)
    assert {:ok, :done} = await(run, 10_000)
    assert_receive {:DOWN, ^ref, :process, ^hub, _}, 5_000
    # No row of the run is left for a conditions process to stop.
    assert :ets.match(Dolphin.Engine.Stops, {:_, :_, :_, :_, :_, run}) == []
  end
end
