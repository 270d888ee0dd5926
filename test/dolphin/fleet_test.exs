defmodule Dolphin.FleetTest do
  use Dolphin.EngineCase, async: false

  alias Dolphin.Fleet
  alias Dolphin.Engine.Watcher
  alias Dolphin.Fleet.{MAVLinkSource, PickError}
  alias Dolphin.Geo
  alias Dolphin.Vehicles.View

  doctest Dolphin.Fleet.VehicleSet
  doctest Dolphin.Vehicles.View

  defp pick(ctx, opts, owner \\ self()), do: Fleet.pick(ctx.fleet, owner, opts)

  defp async_pick(ctx, opts) do
    me = self()
    owner = self()
    spawn_link(fn -> send(me, {:picked, Fleet.pick(ctx.fleet, owner, opts)}) end)
  end

  describe "pick" do
    test "by count, type, payload, id and region", ctx do
      porto = Geo.location(41.15, -8.61, 50)
      [uav, cam, boat] = fake_vehicles(ctx, 1) ++ fake_vehicles(ctx, 1, payloads: [:camera]) ++ fake_vehicles(ctx, 1, type: :usv, position: porto)

      assert {:ok, %VehicleSet{ids: [^boat]}} = pick(ctx, type: :usv, timeout: 0)
      assert {:ok, %VehicleSet{ids: [^cam]}} = pick(ctx, payload: :camera, timeout: 0)
      assert {:ok, %VehicleSet{ids: [^uav]}} = pick(ctx, id: uav, timeout: 0)
      Fleet.release(ctx.fleet, self(), VehicleSet.new([uav, cam, boat]))
      assert {:ok, %VehicleSet{ids: [^boat]}} = pick(ctx, region: Geo.area(porto, 1_000), timeout: 0)
      assert {:ok, %VehicleSet{ids: [^uav, ^cam]}} = pick(ctx, count: 2, type: :uav, timeout: 0)
      assert Fleet.picked(ctx.fleet, self()) == VehicleSet.new([uav, cam, boat])
    end

    test "by airframe: the report's three side-scan submarines, not the boat nor the copter; an unknown airframe is refused at once", ctx do
      subs = fake_vehicles(ctx, 3, type: :uuv, payloads: [:sidescan])
      [_boat] = fake_vehicles(ctx, 1, type: :usv, payloads: [:sidescan])
      [_copter] = fake_vehicles(ctx, 1, payloads: [:sidescan])
      assert {:ok, %VehicleSet{ids: ^subs}} = pick(ctx, count: 3, type: :uuv, airframe: :sub, payload: :sidescan, timeout: 0)
      assert {:error, %PickError{requirement: "1 vehicle, airframe [:plane, :quadplane]"}} = pick(ctx, airframe: [:plane, :quadplane], timeout: 0)
      assert_raise ArgumentError, ~r/pick airframe must be one of \[:copter, :plane, :quadplane, :rover, :boat, :sub\] \(or a list of them\), got: :submarine/, fn -> pick(ctx, airframe: :submarine) end
    end

    test "a pick that cannot be served in time fails, naming the requirement", ctx do
      [v] = fake_vehicles(ctx, 1, type: :ugv)
      assert {:error, %PickError{requirement: "2 vehicles, type :uav, payload [:camera]", message: m}} = pick(ctx, count: 2, type: :uav, payload: :camera, timeout: 10)
      assert m =~ "pick timed out after 10 ms"
      assert m =~ "#{v} (ugv rover, available)"
    end

    test "release_all/2 releases an owner's vehicles and drops its waiting picks at once, while it still lives", ctx do
      [a] = fake_vehicles(ctx, 1)
      owner = spawn_link(fn -> Process.sleep(:infinity) end)
      assert {:ok, %VehicleSet{ids: [^a]}} = pick(ctx, [count: 1, timeout: 0], owner)
      # Its waiting pick (for a vehicle that does not exist yet) and someone else's.
      me = self()
      spawn_link(fn -> send(me, {:owner_picked, Fleet.pick(ctx.fleet, owner, count: 1, timeout: 10_000)}) end)
      async_pick(ctx, count: 1, timeout: 10_000)
      refute_receive {:picked, _}, 50

      :ok = Fleet.release_all(ctx.fleet, owner)
      assert Fleet.picked(ctx.fleet, owner) == VehicleSet.new([])
      assert_receive {:picked, {:ok, %VehicleSet{ids: [^a]}}}, 5_000
      # The owner's own waiting pick was dropped, not served by the next vehicle.
      [_b] = fake_vehicles(ctx, 1)
      refute_receive {:owner_picked, _}, 50
      assert Fleet.picked(ctx.fleet, owner) == VehicleSet.new([])
    end

    test "waiting picks are served as vehicles appear or are released", ctx do
      [a] = fake_vehicles(ctx, 1, pick: true)
      async_pick(ctx, count: 2, timeout: 10_000)
      refute_receive {:picked, _}, 50
      [b] = fake_vehicles(ctx, 1)
      refute_receive {:picked, _}, 50
      :ok = Fleet.release(ctx.fleet, self(), VehicleSet.new(a))
      assert_receive {:picked, {:ok, %VehicleSet{ids: ids}}}, 5_000
      assert Enum.sort(ids) == Enum.sort([a, b])
    end

    test "first come, first served: an earlier waiting pick keeps the vehicles it can use", ctx do
      async_pick(ctx, count: 2, timeout: 10_000)
      # Wait until the first pick waits, then ask a smaller one.
      Dolphin.Test.Wait.until(fn -> :sys.get_state(ctx.fleet).waiters != [] end)
      async_pick(ctx, count: 1, timeout: 10_000)
      Dolphin.Test.Wait.until(fn -> length(:sys.get_state(ctx.fleet).waiters) == 2 end)
      [a] = fake_vehicles(ctx, 1)
      refute_receive {:picked, _}, 50
      [b] = fake_vehicles(ctx, 1)
      assert_receive {:picked, {:ok, %VehicleSet{ids: [^a, ^b]}}}, 5_000
      refute_receive {:picked, _}, 50
      [c] = fake_vehicles(ctx, 1)
      assert_receive {:picked, {:ok, %VehicleSet{ids: [^c]}}}, 5_000
    end

    test "a waiting pick nobody earlier can use is served at once", ctx do
      async_pick(ctx, type: :usv, timeout: 10_000)
      Dolphin.Test.Wait.until(fn -> :sys.get_state(ctx.fleet).waiters != [] end)
      [uav] = fake_vehicles(ctx, 1)
      assert {:ok, %VehicleSet{ids: [^uav]}} = pick(ctx, type: :uav, timeout: 1_000)
    end

    test "lost vehicles are not picked; an owner that ends releases its vehicles", ctx do
      [a, b] = fake_vehicles(ctx, 2)
      FakeSource.lose(ctx.source, a)
      owner = spawn(fn -> Process.sleep(:infinity) end)
      assert {:ok, %VehicleSet{ids: [^b]}} = pick(ctx, [timeout: 1_000], owner)
      assert {:error, %PickError{}} = pick(ctx, timeout: 0)
      Process.exit(owner, :kill)
      assert {:ok, %VehicleSet{ids: [^b]}} = pick(ctx, timeout: 1_000)
      FakeSource.reconnect(ctx.source, a)
      assert {:ok, %VehicleSet{ids: [^a]}} = pick(ctx, timeout: 1_000)
    end

    test "a vehicle its source no longer knows is not given", ctx do
      [a, b] = fake_vehicles(ctx, 2)
      FakeSource.remove(ctx.source, a)
      assert {:ok, %VehicleSet{ids: [^b]}} = pick(ctx, timeout: 1_000)
      refute Enum.any?(Fleet.vehicles(ctx.fleet), &(&1.vehicle.id == a))
    end

    test "caller mistakes raise ArgumentError", ctx do
      assert_raise ArgumentError, ~r/unknown pick option {:kind, :uav}/, fn -> pick(ctx, kind: :uav) end
      assert_raise ArgumentError, ~r/count must be a positive integer, got: 0/, fn -> pick(ctx, count: 0) end
      assert_raise ArgumentError, ~r/type must be one of/, fn -> pick(ctx, type: "UAV") end
      assert_raise ArgumentError, ~r/region must be an area/, fn -> pick(ctx, region: 3) end
      assert_raise ArgumentError, ~r/timeout must be milliseconds/, fn -> pick(ctx, timeout: -1) end
    end
  end

  describe "connection timeout" do
    test "applies to vehicles picked and to be picked", ctx do
      [a, b] = fake_vehicles(ctx, 2)
      {:ok, _} = pick(ctx, id: a, timeout: 0)
      :ok = Fleet.set_connection_timeout(ctx.fleet, self(), 600_000)
      assert FakeSource.timeout(ctx.source, a) == 600_000
      assert FakeSource.timeout(ctx.source, b) == nil
      {:ok, _} = pick(ctx, id: b, timeout: 0)
      assert FakeSource.timeout(ctx.source, b) == 600_000
    end
  end

  describe "events" do
    test "vehicles, picks and state changes are events" do
      source = :"fleet_events_#{System.unique_integer([:positive])}"
      start_supervised!({FakeSource, name: source}, id: :events_source)
      start_supervised!({Fleet, name: :fleet_with_events, source: FakeSource.source(source)}, id: :events_fleet)
      id = 200_000 + System.unique_integer([:positive])
      FakeSource.add(source, id, type: :ugv)
      assert_receive {:dolphin, :events, %{event: :vehicle_discovered, vehicle: ^id, type: :ugv}}, 5_000
      FakeSource.set(source, id, mode: :guided, armed?: true, mission_progress: {3, 9})
      assert_receive {:dolphin, :events, %{event: :mode_changed, vehicle: ^id, mode: :guided}}, 5_000
      assert_receive {:dolphin, :events, %{event: :armed, vehicle: ^id}}
      assert_receive {:dolphin, :events, %{event: :mission_item_reached, vehicle: ^id, seq: 3}}
      {:ok, set} = Fleet.pick(:fleet_with_events, self(), id: id, timeout: 1_000)
      assert_receive {:dolphin, :events, %{event: :picked, vehicles: [^id]}}
      FakeSource.lose(source, id)
      assert_receive {:dolphin, :events, %{event: :vehicle_lost, vehicle: ^id}}, 5_000
      Fleet.release(:fleet_with_events, self(), set)
      assert_receive {:dolphin, :events, %{event: :released, vehicles: [^id]}}

      # Forgotten (a finished simulation's vehicle), then heard again: discovered anew.
      FakeSource.remove(source, id)
      FakeSource.add(source, id, type: :ugv)
      assert_receive {:dolphin, :events, %{event: :vehicle_discovered, vehicle: ^id, type: :ugv}}, 5_000
    end
  end

  describe "state" do
    test "of one vehicle; a set of another size is a caller mistake", ctx do
      [a, b] = fake_vehicles(ctx, 2, battery: 0.5)
      assert %View{battery: 0.5} = Watcher.vehicle(VehicleSet.new(a))
      assert %View{battery: 0.5} = Watcher.vehicle(b)
      assert_raise ArgumentError, ~r/battery needs a one-vehicle set, got: #Vehicles<\[/, fn -> Watcher.vehicle(VehicleSet.new([a, b]), :battery) end
      assert_raise ArgumentError, ~r/unknown vehicle 77/, fn -> Watcher.vehicle(77) end
    end
  end

  describe "the MAVLink source" do
    test "a vehicle's view of its state: type class, payloads, battery, position, progress" do
      state = %{
        Dolphin.Vehicles.State.new(9)
        | type: 2,
          components: MapSet.new([:camera]),
          battery: 0.42,
          position: %{lat: 40.1, lon: -7.3, alt: 900.0, relative_alt: 80.0, heading: 90.0},
          mode: :auto,
          armed: true,
          mission: %{current: 3, total: 7, state: :active, reached: 2},
          landed: :in_air
      }

      v = View.of(state, false, [])
      assert %View{id: 9, type: :uav, payloads: [:camera], battery: 0.42, mode: :auto, armed?: true, mission_progress: {2, 7}, landed: :in_air, relative_altitude: 80.0, connected?: true} = v
      assert %Geo.Location{lat: 40.1, lon: -7.3, h: 900.0} = v.position
      assert View.of(%{state | type: 11}, false, []).type == :usv
      assert View.of(state, true, [:sidescan]) |> Map.take([:connected?, :payloads]) == %{connected?: false, payloads: [:camera, :sidescan]}
      # No MISSION_CURRENT yet: the progress is unknown, not "nothing reached of no items".
      assert View.of(%{state | mission: %{current: nil, total: nil, state: nil, reached: nil}}, false, []).mission_progress == nil
      assert View.of(%{state | mission: %{current: 0, total: 4, state: :active, reached: nil}}, false, []).mission_progress == {0, 4}
    end

    test "an unknown vehicle" do
      assert {:error, :unknown_vehicle} = MAVLinkSource.vehicle(nil, 254)
    end
  end
end
