defmodule Dolphin.Cluster.PicksTest do
  # Picks are cluster-wide: two controllers (this node and a :peer one) that
  # follow one station pick from its vehicles at the same moment, round after
  # round, with random counts; no vehicle is ever given to both. Distribution,
  # the clock and the fleet are global: not async.
  use ExUnit.Case, async: false

  @moduletag :cluster
  @moduletag :capture_log
  @moduletag timeout: 180_000

  alias Dolphin.Fleet
  alias Dolphin.Test.{Cluster, Wait}

  @speedup 20
  @ids [41, 42, 43, 44]
  @rounds 12

  setup do: Cluster.setup_controller(@speedup)

  # A pick by `owner` through the fleet of `where` (:here or a peer).
  defp pick(:here, owner, opts), do: Fleet.pick(Fleet, owner, opts)
  defp pick(peer, owner, opts), do: Cluster.call(peer, Fleet, :pick, [Fleet, owner, opts], 60_000)

  defp release_all(:here, owner), do: Fleet.release_all(Fleet, owner)
  defp release_all(peer, owner), do: Cluster.call(peer, Fleet, :release_all, [Fleet, owner])

  test "two controllers picking at the same moment never get one vehicle (randomized rounds)" do
    station = Cluster.start_station("gs1", sysids: @ids)
    other = Cluster.start_node("c2")
    assert :ok = Dolphin.Cluster.join(station.node)
    assert :ok = Cluster.call(other.peer, Dolphin.Cluster, :join, [station.node])
    Cluster.await_vehicles(@ids)

    Wait.until(
      fn -> Enum.all?(@ids, &match?({:ok, %{connected?: true, type: :uav}}, Cluster.call(other.peer, Dolphin.Vehicles, :view, [&1]))) end,
      30_000,
      fn -> "the vehicles on the second controller" end
    )

    seed = :erlang.phash2(make_ref())
    :rand.seed(:exsss, {seed, 3, 5})
    here_owner = spawn(fn -> Process.sleep(:infinity) end)
    peer_owner = Cluster.call(other.peer, :erlang, :spawn, [Process, :sleep, [:infinity]])
    sides = [{:here, here_owner}, {other.peer, peer_owner}]

    for round <- 1..@rounds do
      # Together they may ask for more than there is: the one served second
      # then waits, and times out (a pick's timeout is clock time).
      asks = for side <- sides, do: {side, Enum.random(1..3)}

      results =
        asks
        |> Enum.map(fn {{where, owner}, count} -> Task.async(fn -> {count, pick(where, owner, count: count, timeout: 1_000)} end) end)
        |> Enum.map(&Task.await(&1, 90_000))

      note = "seed #{seed}, round #{round}: #{inspect(results)}"
      given = for {_count, {:ok, set}} <- results, do: Fleet.VehicleSet.ids(set)
      all = List.flatten(given)
      assert length(all) == length(Enum.uniq(all)), "one vehicle given twice: " <> note

      # Whatever fits is given: both picks succeed when the counts fit in
      # the fleet, and at least one always does.
      total = asks |> Enum.map(&elem(&1, 1)) |> Enum.sum()
      if total <= length(@ids), do: assert(length(given) == 2, note), else: assert(given != [], note)

      for {where, owner} <- sides, do: :ok = release_all(where, owner)
    end
  end

  test "a vehicle the controller names apart is one vehicle to picks: its station's own script and the controller never both get it" do
    gs1 = Cluster.start_station("gs1", sysids: [30], sim: [home: %{lat: 40.444233, lon: -7.375234, alt: 820.0}])
    gs2 = Cluster.start_station("gs2", sysids: [30], sim: [home: %{lat: 40.454233, lon: -7.375234, alt: 820.0}])
    Dolphin.Events.subscribe()
    assert :ok = Dolphin.Cluster.join(gs1.node)
    Cluster.await_vehicles([30])
    assert :ok = Dolphin.Cluster.join(gs2.node)
    assert_receive {:dolphin, :events, %{event: :vehicle_conflict, vehicle: 30, other: apart}}, 20_000
    Cluster.await_vehicles([30, apart])
    assert Dolphin.Cluster.Mirror.heard_as(apart) == [{gs2.node, 30}]

    here = spawn(fn -> Process.sleep(:infinity) end)
    there = Cluster.call(gs2.peer, :erlang, :spawn, [Process, :sleep, [:infinity]])

    # gs2's own script has its 30: the controller cannot have it as the name it gave it.
    assert {:ok, _} = pick(gs2.peer, there, id: 30, timeout: 1_000)
    assert {:error, _} = pick(:here, here, id: apart, timeout: 1_000)
    :ok = release_all(gs2.peer, there)

    # And the other way round.
    assert {:ok, _} = pick(:here, here, id: apart, timeout: 1_000)
    assert {:error, _} = pick(gs2.peer, there, id: 30, timeout: 1_000)
    :ok = release_all(:here, here)
    assert {:ok, _} = pick(gs2.peer, there, id: 30, timeout: 1_000)
    :ok = release_all(gs2.peer, there)

    # gs1's 30 is another vehicle: picked here while gs2's is picked there
    # only if the plain id is free; the controller's 30 and gs2's 30 share a
    # name, which a claim holds too (it errs towards refusing).
    assert {:ok, _} = pick(:here, here, id: 30, timeout: 1_000)
    assert {:ok, _} = pick(:here, here, id: apart, timeout: 1_000)
    :ok = release_all(:here, here)
  end
end
