defmodule Dolphin.ClusterTest do
  # Ground stations on :peer nodes, this node their controller (see
  # Dolphin.Test.Cluster). Distribution, the clock and the fleet are global: not async.
  use ExUnit.Case, async: false

  @moduletag :cluster
  @moduletag timeout: 120_000

  alias Dolphin.{Telemetry, Vehicles}
  alias Dolphin.Test.Cluster

  @speedup 50

  setup do
    Dolphin.Clock.set_speedup(@speedup)
    Cluster.start_controller()
    Dolphin.Fleet.set_source({Dolphin.Fleet.MAVLinkSource, nil})
    :ok
  end

  defp hop_script(ids) do
    missions =
      for {id, i} <- Enum.with_index(ids, 1) do
        """
        v#{i} = pick(id: #{id}, timeout: seconds(60))
        execute wait_for(position(v#{i}) != nil)
        h#{i} = position(v#{i})
        hop#{i} =
          mission "Hop #{id}" do
            home h#{i}
            take_off %{h#{i} | h: h#{i}.h + 15}
            move 30, 0, 0
            return_home_and_land()
          end
        """
      end

    tasks = Enum.map_join(1..length(ids), ", ", &"v#{&1} => hop#{&1}")
    {:ok, script} = Dolphin.Script.compile_string("use Dolphin.Script\n" <> Enum.join(missions) <> "execute %{#{tasks}}\n", "hops.exs")
    script
  end

  test "a script on the controller flies vehicles of two stations to completion" do
    gs1 = Cluster.start_station("gs1", sysids: [1])
    gs2 = Cluster.start_station("gs2", sysids: [11])
    assert :ok = Dolphin.Cluster.join(gs1.node)
    assert :ok = Dolphin.Cluster.join(gs2.node)
    Cluster.await_vehicles([1, 11])
    assert [1, 11] = Vehicles.list()
    assert node(Vehicles.whereis(1)) == gs1.node
    assert node(Vehicles.whereis(11)) == gs2.node

    Telemetry.subscribe()
    assert {:ok, %{result: :done}} = Dolphin.Script.run(hop_script([1, 11]))
    # The controller's events come from both stations' vehicles.
    events = flush()
    for id <- [1, 11], do: assert(Enum.any?(events, &match?(%{event: :armed, vehicle: ^id}, &1)))
  end

  defp flush(acc \\ []) do
    receive do
      {:dolphin, :events, e} -> flush([e | acc])
    after
      0 -> Enum.reverse(acc)
    end
  end
end
