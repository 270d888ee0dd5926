defmodule Dolphin.Vehicles.SharedSystemIdTest do
  # Vehicles that all left the factory as system id 1 (simulated vehicles of separate
  # networks, each with its own autopilot unique id), heard on three links, or on one
  # udpin port from two addresses: each is a vehicle of its own, named by its system
  # id (the first heard) or "1@NETWORK", and each flies its own mission. Real UDP on
  # 127.0.0.1. Its own Dolphin.Instance (its vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.{Events, Sim, Vehicles}
  alias Dolphin.Test.{GroundStation, Hops, Wait}

  doctest Dolphin.Vehicles.Id

  @moduletag timeout: 300_000

  @speedup 10

  setup do
    Dolphin.Test.Instance.on_exit(&GroundStation.forget_vehicles/0)
    Events.subscribe()
    :ok
  end

  # Simulated vehicles with system id 1, one per network, each sending to its
  # port; returns {sim, network} pairs once the ground station knows each of
  # them as a vehicle (named by the address it sends from).
  defp fleet_of_ones(ports) do
    sims =
      for {port, i} <- Enum.with_index(ports, 1) do
        {:ok, [sim]} = Sim.start(count: 1, gcs: port, network: "n#{i}", speedup: @speedup, home: %{lat: 40.444233 + i * 0.0005, lon: -7.375234, alt: 820.0})
        {:ok, %{port: sim_port}} = Sim.info(sim)
        {sim, "127.0.0.1:#{sim_port}"}
      end

    Wait.until(fn -> length(Vehicles.list()) == length(ports) and Enum.all?(Vehicles.list(), &match?({:ok, %{type: :uav, uid: uid}} when uid != nil, Vehicles.view(&1))) end, 3_000, fn ->
      "#{length(ports)} vehicles with system id 1; known: #{inspect(Vehicles.list())}"
    end)

    sims
  end

  # The vehicle the ground station knows as sending from `network`.
  defp vehicle_on(network), do: Enum.find(Vehicles.list(), fn id -> match?({:ok, %{network: ^network}}, Vehicles.view(id)) end)

  # Each vehicle (by `names`, what the script calls it) flies a hop of its
  # own: up to 10 + 5 i metres, i x 20 m north, home.
  defp hops(names), do: Hops.script(for {name, i} <- Enum.with_index(names, 1), do: {name, 10 + 5 * i, 20 * i})

  # The take-off height above home of the mission on simulated vehicle `sim`.
  defp take_off_height(sim) do
    {:ok, %{mission: items, home: home}} = Sim.info(sim)
    %{z: z} = Enum.find(items, &(&1.command == 22))
    round(z - home.alt)
  end

  defp flown_heights(sims), do: Enum.map(sims, fn {sim, _network} -> take_off_height(sim) end)

  test "three vehicles that are all system id 1, on three links, are three vehicles, and each flies its own mission" do
    ports = for _ <- 1..3, do: GroundStation.open()
    sims = fleet_of_ones(ports)

    # The first heard is 1; the others are named by their networks.
    ids = Vehicles.list()
    assert 1 in ids
    assert length(Enum.filter(ids, &is_binary/1)) == 2
    for {_sim, network} <- sims, do: assert(vehicle_on(network) != nil, "no vehicle heard from #{network}: #{inspect(ids)}")
    uids = for id <- ids, {:ok, view} = Vehicles.view(id), do: view.uid
    assert length(Enum.uniq(uids)) == 3

    events = Wait.received_events()
    shared = for %{event: :system_id_shared} = e <- events, do: e.other
    assert Enum.sort(shared) == Enum.sort(Enum.filter(ids, &is_binary/1))

    # The script names each by its qualified name, the first one too.
    names = for {_sim, network} <- sims, do: "1@#{network}"
    assert {:ok, %{result: :done}} = Dolphin.Script.run(hops(names))
    assert flown_heights(sims) == [15, 20, 25]

    # Each vehicle reported its own mission's items reached, under its own id.
    events = Wait.received_events()

    for {_sim, network} <- sims do
      id = vehicle_on(network)
      assert Enum.any?(events, &match?(%{event: :mission_item_reached, vehicle: ^id}, &1)), "#{inspect(id)} reached nothing"
    end
  end

  test "two vehicles with system id 1 on one udpin port, from two addresses, are two vehicles, and each flies its own mission" do
    port = GroundStation.open()
    sims = fleet_of_ones([port, port])
    [{_, first}, {_, second}] = sims
    one = vehicle_on(first)
    other = vehicle_on(second)
    assert MapSet.new([one, other]) == MapSet.new([1, "1@" <> if(one == 1, do: second, else: first)])

    # Commands reach the right one of the two.
    assert {:ok, :accepted} = Vehicles.set_mode(other, :guided)
    Wait.until(fn -> match?({:ok, %{mode: :guided}}, Vehicles.view(other)) end, 3_000, fn -> "#{inspect(other)} in GUIDED" end)
    assert {:ok, %{mode: mode}} = Vehicles.view(one)
    assert mode != :guided

    # The console lists both, and takes the name wherever it takes an id.
    listing = ExUnit.CaptureIO.capture_io(fn -> Dolphin.Console.vehicles() end)
    assert listing =~ ~r/^\s*1\s/m
    assert listing =~ other
    # (ALT_HOLD: a mode that needs no position estimate, which may not be ready yet.)
    said = ExUnit.CaptureIO.capture_io(fn -> Dolphin.Console.mode(other, :alt_hold) end)
    assert said =~ "vehicle #{other}: mode ALT_HOLD", said
    Wait.until(fn -> match?({:ok, %{mode: :alt_hold}}, Vehicles.view(other)) end, 3_000, fn -> "#{inspect(other)} in ALT_HOLD" end)
    assert {:ok, %{mode: :stabilize}} = Vehicles.view(one)
    Vehicles.set_mode(other, :guided)

    # The script names them as vehicles() lists them.
    assert {:ok, %{result: :done}} = Dolphin.Script.run(hops([vehicle_on(first), vehicle_on(second)]))
    assert flown_heights(sims) == [15, 20]
  end

  test "on a link given a network's name, a vehicle sharing a system id is named by it; a second one of that id on it, by its address too" do
    plain = GroundStation.open()
    radio = GroundStation.open(network: "radio2")
    [{_, _}] = fleet_of_ones([plain])

    {:ok, [a]} = Sim.start(count: 1, gcs: radio, network: "a", speedup: @speedup, home: %{lat: 40.4452, lon: -7.375234, alt: 820.0})
    {:ok, [b]} = Sim.start(count: 1, gcs: radio, network: "b", speedup: @speedup, home: %{lat: 40.4457, lon: -7.375234, alt: 820.0})
    addresses = for sim <- [a, b], {:ok, %{port: port}} = Sim.info(sim), do: "1@127.0.0.1:#{port}"
    Wait.until(fn -> length(Vehicles.list()) == 3 end, 3_000, fn -> "three vehicles with system id 1; known: #{inspect(Vehicles.list())}" end)

    assert [1, by_address, "1@radio2"] = Vehicles.list()
    assert by_address in addresses
    assert {:ok, %{network: "radio2"}} = Vehicles.view("1@radio2")

    assert {:error, e} = Dolphin.Link.connect("udpin:127.0.0.1:0", network: :radio3)
    assert Exception.message(e) == ~s|udpin:127.0.0.1:0: network: a network's name is some text, such as "radio2", got: :radio3|
  end

  test "the paths of one other autopilot, given away before its vehicle has a view, make one vehicle, and are its for good" do
    via = fn port -> {"test-shared-#{port}", {{127, 0, 0, 1}, port}} end
    # Two paths of autopilot 99 refused in one pass: one vehicle.
    first = Vehicles.heard_elsewhere(201, via.(5001), 99)
    assert first == "201@127.0.0.1:5001"
    assert Vehicles.heard_elsewhere(201, via.(5002), 99) == first
    # Another autopilot with that system id: another vehicle.
    assert Vehicles.heard_elsewhere(201, via.(5003), 77) == "201@127.0.0.1:5003"
    assert Dolphin.Vehicles.Views.vehicle_on(201, via.(5002)) == first
    # Forgetting the vehicle keeps its paths its own: heard again, it is discovered under the same name.
    :ok = Vehicles.forget(first)
    assert Dolphin.Vehicles.Views.vehicle_on(201, via.(5001)) == first
    assert Dolphin.Vehicles.Views.vehicle_on(201, {"elsewhere", nil}) == 201
  end

  test "a fleet of fake vehicles may name one by its qualified name" do
    name = :"fake_shared_#{System.unique_integer([:positive])}"
    start_supervised!({Dolphin.Fleet.FakeSource, name: name})
    :ok = Dolphin.Fleet.FakeSource.add(name, 1)
    :ok = Dolphin.Fleet.FakeSource.add(name, "1@radio2")
    assert Dolphin.Fleet.FakeSource.list(name) == [1, "1@radio2"]
    assert Enum.map(Dolphin.Fleet.FakeSource.views(name), & &1.id) == [1, "1@radio2"]
  end

  test "a vehicle id is a system id or a qualified name; anything else is refused where a user gives it" do
    assert_raise ArgumentError, ~r/pick id must be a vehicle id .*got: "1@"/, fn -> Dolphin.Fleet.requirement!(id: "1@") end
    assert_raise ArgumentError, ~r/a vehicle is a system id/, fn -> Dolphin.Fleet.VehicleSet.new(["radio"]) end
    assert Dolphin.Fleet.VehicleSet.new([2, "1@radio2", 1]).ids == [1, 2, "1@radio2"]
  end
end
