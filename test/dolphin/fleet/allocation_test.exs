defmodule Dolphin.Fleet.AllocationTest do
  use Dolphin.EngineCase, async: false

  import Dolphin.DSL, only: [>>>: 2, |||: 2]

  alias Dolphin.Engine.{Run, Task}
  alias Dolphin.Fleet.{Allocation, AllocationError}
  alias Dolphin.Vehicles.View

  doctest Dolphin.Fleet.Allocation

  defp tp(name, opts \\ []), do: FakePlatform.task(name, opts)
  defp v(id, type \\ :uav, payloads \\ []), do: %View{id: id, type: type, airframe: View.stand_in_airframe(type), payloads: payloads}

  defp solve(task, vehicles) do
    {tree, _} = Task.number(Task.new!(task), 1)
    leaves = Run.leaves(tree)
    names = Map.new(leaves, &{&1.id, &1.name})

    case Allocation.solve(leaves, vehicles) do
      {:ok, a} -> {:ok, Map.new(a, fn {id, vid} -> {names[id], vid} end)}
      error -> error
    end
  end

  test "concurrent tasks get distinct vehicles, sequential ones share" do
    assert {:ok, %{"a" => 1, "b" => 2}} = solve(tp("a") ||| tp("b"), [v(1), v(2)])
    assert {:ok, %{"a" => 1, "b" => 1}} = solve(tp("a") >>> tp("b"), [v(1), v(2)])
    # A sequence keeps its vehicle even when it is in a concurrent branch.
    assert {:ok, %{"a" => x, "b" => x, "c" => y}} = solve((tp("a") >>> tp("b")) ||| tp("c"), [v(1), v(2)])
    assert x != y
  end

  test "which tasks may run at the same time: |||, all_of; not one_of, until, during, wait_for, watch" do
    c = fn -> true end
    assert {:ok, %{"a" => 1, "b" => 1}} = solve(one_of([{c, tp("a")}, {c, tp("b")}]), [v(1)])
    assert {:ok, %{"a" => 1, "b" => 2}} = solve(all_of([{c, tp("a")}, {c, tp("b")}]), [v(1), v(2)])
    assert {:error, %AllocationError{}} = solve(all_of([{c, tp("a")}, {c, tp("b")}]), [v(1)])
    assert {:ok, %{"a" => 1, "b" => 1}} = solve(until(tp("a"), c) >>> during(5, tp("b")), [v(1)])
    assert {:ok, %{"a" => 1, "b" => 1}} = solve(wait_for(c, tp("a")) >>> watch(tp("b")), [v(1)])
  end

  test "requirements and on/2 are honoured" do
    assert {:ok, %{"cam" => 2}} = solve(tp("cam", payloads: [:camera]), [v(1), v(2, :uav, [:camera])])
    assert {:ok, %{"boat" => 3}} = solve(tp("boat", type: :usv), [v(1), v(2), v(3, :usv)])
    assert {:ok, %{"one" => 2}} = solve(tp("one", id: 2), [v(1), v(2)])
    assert {:ok, %{"there" => 2}} = solve(on(tp("there"), [2]), [v(1), v(2)])
    assert {:ok, %{"x" => 2}} = solve(on(on(tp("x"), [1, 2]), [2, 3]), [v(1), v(2), v(3)])
  end

  test "a real matching where greedy first fit fails" do
    # First fit gives vehicle 1 (the camera one) to "any" and has nothing for "cam".
    task = tp("any") ||| tp("cam", payloads: [:camera])
    assert {:ok, %{"any" => 2, "cam" => 1}} = solve(task, [v(1, :uav, [:camera]), v(2)])

    # A chain of constraints: each choice pushes the next.
    task = tp("a", type: [:uav, :ugv]) ||| tp("b", type: [:ugv, :usv]) ||| tp("c", type: :usv)
    assert {:ok, %{"a" => 1, "b" => 2, "c" => 3}} = solve(task, [v(2, :ugv), v(1, :uav), v(3, :usv)])
  end

  test "an airframe requirement: a take-off goes to what flies, a raw mission to any vehicle, one of unknown airframe too" do
    home = Dolphin.Geo.location(40.444233, -7.375234, 820)
    up = Dolphin.Mission.new("up", [Dolphin.Mission.Command.take_off(home), Dolphin.Mission.Command.move(10, 0, 0)])
    raw = Dolphin.Mission.new("raw", [Dolphin.Mission.Command.item(16, position: home)])
    boat = v(1, :usv)
    plane = %{v(2) | airframe: :plane}
    airship = %View{id: 3, type: :uav, mav_type: 7}
    assert {:ok, %{"up" => 2}} = solve(up, [boat, airship, plane])
    assert {:error, %AllocationError{message: m}} = solve(up, [boat, airship])
    assert m =~ "no vehicle matches airframe [:copter, :plane, :quadplane]"
    assert m =~ "1 (usv boat), 3 (uav, airframe unknown (airship))"
    assert {:ok, %{"raw" => 3}} = solve(raw, [airship])
  end

  test "impossibility names the task that cannot be served" do
    assert {:error, %AllocationError{task_name: "boat", message: m}} = solve(tp("plane") >>> tp("boat", type: :usv), [v(1)])
    assert m =~ ~s(cannot allocate a vehicle to "boat")
    assert m =~ "no vehicle matches type :usv"
    assert m =~ "1 (uav copter)"

    assert {:error, %AllocationError{task_name: "third", message: m}} = solve(tp("first") ||| tp("second") ||| tp("third"), [v(1), v(2)])
    assert m =~ ~s(needed at the same time by "first")

    assert {:error, %AllocationError{message: m}} = solve(tp("x"), [])
    assert m =~ "pick vehicles first"
  end

  test "runs use only the vehicles the script picked and not busy in another run", ctx do
    [a, b] = fake_vehicles(ctx, 2)
    assert {:error, %AllocationError{}} = run(FakePlatform.task("unpicked"))
    {:ok, _} = Dolphin.Fleet.pick(ctx.fleet, self(), id: a, timeout: 1_000)
    {:ok, first} = start(FakePlatform.task("long", duration: :infinity, notify: self()))
    assert_receive {:fake_platform, :started, %{vehicle: ^a}}, 5_000
    # The only picked vehicle is busy: another run cannot have it.
    assert {:error, %AllocationError{task_name: "second"}} = run(FakePlatform.task("second"))
    {:ok, _} = Dolphin.Fleet.pick(ctx.fleet, self(), id: b, timeout: 1_000)
    assert {:ok, :done} = run(FakePlatform.task("second", duration: 1, notify: self()))
    assert_receive {:fake_platform, :started, %{name: "second", vehicle: ^b}}
    :ok = Dolphin.Engine.stop(first)
    assert {:ok, :stopped} = await(first, 5_000)
    assert [%{busy: nil}, %{busy: nil}] = Enum.filter(Dolphin.Fleet.vehicles(ctx.fleet), &(&1.vehicle.id in [a, b]))
  end
end
