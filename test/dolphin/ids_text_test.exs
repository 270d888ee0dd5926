defmodule Dolphin.IdsTextTest do
  # Vehicle ids are printed as numbers everywhere: a list of ids that all
  # happen to be printable character codes must not come out as a charlist
  # (`[99]` as 'c', `[9]` as '\t').
  use Dolphin.EngineCase, async: false

  import Dolphin.Property

  alias Dolphin.Console.Format
  alias Dolphin.Engine.Failure
  alias Dolphin.Fleet
  alias Dolphin.Fleet.{Allocation, PickError}
  alias Dolphin.Vehicles.View
  alias Dolphin.CLI.StatusBlock

  # The text names `id` as a decimal number and has no charlist in it.
  defp names_id!(text, id) do
    assert text =~ ~r/(?<![0-9])#{id}(?![0-9])/, "#{inspect(text)} does not show vehicle #{id} as a number"
    refute text =~ "'", "#{inspect(text)} prints a charlist"
    refute text =~ "~c", "#{inspect(text)} prints a charlist"
    true
  end

  defp id_gen, do: :proper_types.integer(1, 255)

  test "VehicleSet.format and inspect of a set print ids as numbers" do
    check(
      forall(id_gen(), fn id ->
        names_id!(VehicleSet.format([id]), id)
        names_id!(VehicleSet.format(VehicleSet.new([id, 1])), id)
        names_id!(VehicleSet.format(id), id)
        names_id!(inspect(VehicleSet.new(id)), id)
        names_id!(Dolphin.Engine.Task.format(on(FakePlatform.task("t"), VehicleSet.new(id))), id)
      end),
      numtests: 300
    )
  end

  test "pick errors name the ids asked for as numbers", ctx do
    check(
      forall(id_gen(), fn id ->
        assert {:error, %PickError{requirement: req, message: m}} = Fleet.pick(ctx.fleet, self(), id: id, timeout: 0)
        names_id!(req, id) && names_id!(m, id)
        assert {:error, %PickError{requirement: req, message: m}} = Fleet.pick(ctx.fleet, self(), id: [id], timeout: 0)
        names_id!(req, id) && names_id!(m, id)
      end)
    )
  end

  test "allocation errors name the ids of on/2 and of the candidates as numbers" do
    check(
      forall(id_gen(), fn id ->
        leaf = %{id: 1, name: "survey", requirements: %{id: id}, allowed: [id], path: [{0, :together, 0}]}
        assert {:error, e} = Allocation.solve([leaf], [])
        names_id!(e.message, id)

        # Two concurrent tasks that can only use the same vehicle.
        rival = %{leaf | id: 2, name: "map", requirements: %{}, path: [{0, :together, 1}]}
        assert {:error, e} = Allocation.solve([leaf, rival], [%View{id: id, type: :uav}])
        assert e.message =~ "could use vehicle(s)"
        names_id!(e.message, id)
      end)
    )
  end

  test "console event lines, tables and the status block print ids as numbers" do
    check(
      forall(id_gen(), fn id ->
        req = Fleet.describe(%{count: 1, type: nil, payload: [], region: nil, id: [id]})
        names_id!(req, id)

        events = [
          %{event: :picked, vehicles: [id], requirement: req},
          %{event: :released, vehicles: [id]},
          %{event: :vehicle_discovered, vehicle: id, type: :uav},
          %{event: :armed, vehicle: id},
          %{event: :mission_item_reached, vehicle: id, seq: 1},
          %{event: :path_changed, vehicle: id, from: "udpin:0.0.0.0:14550", to: "udpin:0.0.0.0:14551", reason: :silent},
          %{event: :allocated, run: 1, allocation: %{5 => id}},
          %{event: :task_started, task_id: 5, kind: :fly, name: "go", vehicle: id},
          %{event: :task_progress, task_id: 5, vehicle: id, progress: %{current: 1, total: 3, reached: 1}},
          # An event the console has no line for is shown as its fields.
          %{event: :something_new, vehicles: [id]}
        ]

        for e <- events, do: names_id!(Dolphin.EventText.event_text(e), id)
        names_id!(Dolphin.EventText.event_text(%{event: :task_finished, task_id: 5, kind: :fly, name: "go", vehicle: id, result: :done, reason: nil}), id)

        assert Format.task_state(nil, %{event: :task_progress, progress: %{vehicles: [id]}}) |> names_id!(id)

        row = %{id: id, type: "uav", airframe: "copter", mode: :guided, armed: true, battery: 0.5, lat: 1.0, lon: 2.0, alt: 3.0, link: nil, seen_ms: 10, lost?: false, activity: nil}
        names_id!(Format.vehicles([row]), id)

        tree = Format.task_tree([], [%{run: 1, text: "run 1"}], [%{run: 1, task_id: 5, parent_id: nil, kind: :fly, name: "go", vehicle: id}], %{})
        names_id!(tree, id)

        names_id!(StatusBlock.vehicle_line(%View{id: id, mission_progress: {0, 0}}, "go"), id)
        names_id!(Failure.format_reason({:no_such_vehicles, [id]}), id)
        names_id!(Dolphin.EventText.event_text(%{event: :signal_posted, key: :ready, value: [id]}), id)
        names_id!(Dolphin.Console.Runs.result_text({:unexpected, [id]}), id)

        # A script's message of a list of ids.
        :ok = Dolphin.Script.message([id])
        assert_receive {:dolphin, :events, %{event: :message, text: text}}
        names_id!(text, id)
      end)
    )
  end

  test "the fleet's picked and released events name vehicle 9 as 9", ctx do
    fleet = :"ids_fleet_#{System.unique_integer([:positive])}"
    start_supervised!({Fleet, name: fleet, source: FakeSource.source(ctx.source), events: true}, id: fleet)
    FakeSource.add(ctx.source, 9)
    _ = Fleet.vehicles(fleet)

    assert {:ok, set} = Fleet.pick(fleet, self(), id: 9, timeout: 5_000)
    assert_receive {:dolphin, :events, %{event: :picked, vehicles: [9]} = picked}, 5_000
    assert Dolphin.EventText.event_text(picked) == "picked [9] (1 vehicle, id [9])"

    Fleet.release(fleet, self(), set)
    assert_receive {:dolphin, :events, %{event: :released, vehicles: [9]} = released}, 5_000
    assert Dolphin.EventText.event_text(released) == "released [9]"
  end
end
