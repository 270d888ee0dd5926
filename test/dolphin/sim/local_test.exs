defmodule Dolphin.Sim.LocalTest do
  # The simulated fleet of `--sim N` beyond one network: networks of a few
  # vehicles here (`:network_size`), the same rule as 254 a network. Real
  # UDP on 127.0.0.1; its own Dolphin.Instance (vehicles, links, clock): async.
  use ExUnit.Case, async: true

  alias Dolphin.{Sim, Vehicles}
  alias Dolphin.Sim.Local
  alias Dolphin.Test.{Hops, Wait}

  doctest Dolphin.Sim.Local

  @moduletag timeout: 300_000

  setup do
    Dolphin.Test.Instance.start!()
    Dolphin.Clock.set_speedup(10)
    :ok
  end

  test "a fleet larger than a network is several networks: the first's vehicles named by system id, the others' SYSID@simK, each its own vehicle that flies its own mission" do
    {:ok, sim} = Local.start(5, network_size: 2)

    assert sim.sysids == [1, 2, "1@sim2", "2@sim2", "1@sim3"]
    assert Enum.map(sim.networks, &{&1.name, &1.sysids}) == [{nil, [1, 2]}, {"sim2", [1, 2]}, {"sim3", [1]}]
    [p1, p2, p3] = Enum.map(sim.networks, & &1.port)
    assert Local.describe(sim) == "[1..2] on 127.0.0.1:#{p1}, [1..2]@sim2 on 127.0.0.1:#{p2}, [1]@sim3 on 127.0.0.1:#{p3}"

    # Five vehicles, five autopilots, each on the network it was started on.
    assert Vehicles.list() == Enum.sort(sim.sysids)
    Wait.until(fn -> Enum.all?(sim.sysids, &match?({:ok, %{uid: uid}} when uid != nil, Vehicles.view(&1))) end, 3_000, fn -> "every vehicle's unique id" end)
    views = for id <- sim.sysids, {:ok, view} = Vehicles.view(id), do: view
    assert length(Enum.uniq(Enum.map(views, & &1.uid))) == 5
    assert Enum.map(views, & &1.network) |> Enum.drop(2) == ["sim2", "sim2", "sim3"]

    # A script names them as the ground station does; each flies its own hop.
    assert {:ok, %{result: :done}} = Dolphin.Script.run(Hops.script([{1, 10, 20}, {"2@sim2", 15, 40}]))

    took_off = fn key ->
      {:ok, %{mission: items, home: home}} = Sim.info(key)
      Enum.find_value(items, &(&1.command == 22 && round(&1.z - home.alt)))
    end

    assert {took_off.(1), took_off.({2, 2})} == {10, 15}
    assert {:ok, %{mission: []}} = Sim.info(2)

    :ok = Local.stop(sim)
    assert Vehicles.list() == []
    assert Sim.vehicles() == []
  end

  test "a fleet stopped leaves its names to the next: started again, the same vehicles are named alike" do
    {:ok, sim} = Local.start(3, network_size: 2)
    assert sim.sysids == [1, 2, "1@sim2"]
    :ok = Local.stop(sim)
    {:ok, again} = Local.start(3, network_size: 2)
    assert again.sysids == [1, 2, "1@sim2"]
    assert Enum.sort(Vehicles.list()) == [1, 2, "1@sim2"]
    :ok = Local.stop(again)
  end

  test "a fleet that does not fit, or networks of no size, are refused before anything starts" do
    assert {:error, e} = Local.start(2 * 64 + 1, network_size: 2)
    assert Exception.message(e) == "--sim: 129 vehicles: at most 128 (64 networks of 2)"
    assert {:error, e} = Local.start(3, network_size: 0)
    assert Exception.message(e) == "--sim: a network of 0 vehicles: from 1 to 254"
    assert Vehicles.list() == [] and Sim.vehicles() == []
    assert Local.max_vehicles() == 254 * 64
  end
end
