defmodule Dolphin.Fleet.ClaimsTest do
  # Claims from several :peer nodes at once (Dolphin.Test.Cluster): global
  # names and distribution are shared state, not async.
  use ExUnit.Case, async: false

  @moduletag :cluster
  @moduletag timeout: 120_000
  @moduletag :capture_log

  alias Dolphin.Fleet.Claims
  alias Dolphin.Test.{Cluster, Wait}

  @ids 1..6
  @rounds 20

  setup do
    Cluster.start_controller()
    on_exit(fn -> if Node.alive?(), do: Claims.release(Enum.to_list(@ids) ++ [9]) end)
    :ok
  end

  defp node_with_owner(name) do
    n = Cluster.start_node(name)
    true = Node.connect(n.node)
    :ok = :global.sync()
    :ok = Cluster.call(n.peer, :global, :sync, [])
    owner = Cluster.call(n.peer, :erlang, :spawn, [Process, :sleep, [:infinity]])
    Map.put(n, :owner, owner)
  end

  defp claim_on(%{peer: peer}, ids, owner), do: Cluster.call(peer, Claims, :claim, [ids, owner])
  defp claim_on(:here, ids, owner), do: Claims.claim(ids, owner)

  test "concurrent claims from three nodes never give one vehicle to two owners (randomized rounds)" do
    seed = :erlang.phash2(make_ref())
    :rand.seed(:exsss, {seed, 7, 11})
    here = %{where: :here, owner: spawn(fn -> Process.sleep(:infinity) end)}
    nodes = [here | Enum.map(["c1", "c2"], &(node_with_owner(&1) |> Map.put(:where, nil)))]
    :global.sync()

    for round <- 1..@rounds do
      asks = for n <- nodes, do: {n, Enum.take_random(@ids, Enum.random(1..3))}

      results =
        asks
        |> Enum.map(fn {n, ids} -> Task.async(fn -> {n.owner, ids, claim_on(n.where || n, ids, n.owner)} end) end)
        |> Enum.map(&Task.await(&1, 30_000))

      won = for {owner, ids, :ok} <- results, do: {owner, ids}
      note = "seed #{seed}, round #{round}: #{inspect(results)}"

      # No id in two successful claims, and each is its owner's now.
      all = Enum.flat_map(won, &elem(&1, 1))
      assert length(all) == length(Enum.uniq(all)), note
      for {owner, ids} <- won, id <- ids, do: assert(Claims.owner_of(id) == owner, note)

      # A refused claim names ids it asked for, which someone else holds.
      for {owner, ids, {:error, {:taken, taken}}} <- results do
        assert taken != [] and Enum.all?(taken, &(&1 in ids)), note
        assert Enum.all?(taken, fn id -> Claims.owner_of(id) not in [nil, owner] end), note
      end

      # At least one of the claims that asked for a free id won (serialized, not all refused).
      assert won != [], note
      :ok = Claims.release(Enum.to_list(@ids))
      assert Enum.all?(@ids, &(Claims.owner_of(&1) == nil)), note
    end
  end

  test "a release on one node is heard by a fleet on another; a claim whose owner ends is gone" do
    c1 = node_with_owner("c1")
    :ok = Claims.watch()
    me = self()
    Wait.until(fn -> me in Cluster.call(c1.peer, :pg, :get_members, [Dolphin.Cluster.scope(), :fleets]) end, 10_000, fn -> "the fleet group on c1" end)

    assert :ok = claim_on(c1, [3, 4], c1.owner)
    assert {:error, {:taken, [4]}} = Claims.claim([4, 5], self())
    assert :ok = Cluster.call(c1.peer, Claims, :release, [[3, 4]])
    assert_receive {Claims, :released, [3, 4]}, 5_000
    assert :ok = Claims.claim([4, 5], self())
    :ok = Claims.release([4, 5])

    assert :ok = claim_on(c1, [6], c1.owner)
    # Its holder lives on the owner's node, supervised there.
    holder = :global.whereis_name({Claims, 6})
    assert node(holder) == c1.node
    assert holder in Cluster.call(c1.peer, Task.Supervisor, :children, [Dolphin.Fleet.ClaimHolders])
    Process.exit(c1.owner, :kill)
    Wait.until(fn -> Claims.owner_of(6) == nil end, 10_000, fn -> "the claim of a dead owner gone" end)
  end

  test "after a netsplit with one vehicle claimed on both sides, one claim stays and no owner is stopped" do
    c1 = node_with_owner("c1")
    mine = spawn(fn -> Process.sleep(:infinity) end)
    assert :ok = Claims.claim([9], mine)

    # Cut off, c1 claims the same vehicle for its own owner.
    assert :ok = claim_while_cut_off(c1, [9], 5)

    true = Node.connect(c1.node)
    :global.sync()
    Wait.until(fn -> Claims.owner_of(9) == Cluster.call(c1.peer, Claims, :owner_of, [9]) end, 10_000, fn -> "one owner on both sides" end)
    assert Claims.owner_of(9) in [mine, c1.owner]
    assert Process.alive?(mine)
    assert Cluster.call(c1.peer, Process, :alive?, [c1.owner])
  end

  # Cuts c1 off and claims `ids` there for its owner. Any message between the
  # two nodes (a fleet told of a release, :global's own traffic) connects
  # them again at once, and c1 then sees the claim again: the cut and the
  # claim are tried again then, a few times.
  defp claim_while_cut_off(c1, ids, tries) do
    true = :erlang.disconnect_node(c1.node)
    Wait.until(fn -> Cluster.call(c1.peer, Claims, :owner_of, [hd(ids)]) == nil end, 10_000, fn -> "c1 alone" end)

    case claim_on(c1, ids, c1.owner) do
      {:error, {:taken, _}} when tries > 1 -> claim_while_cut_off(c1, ids, tries - 1)
      result -> result
    end
  end

  test "alone (no distribution), claims are not made: every claim succeeds at once" do
    # A peer node without a name: no distribution.
    paths = Enum.flat_map(:code.get_path(), &[~c"-pa", &1])
    {:ok, peer, :nonode@nohost} = :peer.start(%{connection: :standard_io, args: paths})
    on_exit(fn -> :peer.stop(peer) end)
    {:ok, _} = Cluster.call(peer, Application, :ensure_all_started, [:dolphin])
    refute Cluster.call(peer, Node, :alive?, [])
    assert :ok = Cluster.call(peer, Claims, :claim, [[1], self()])
    assert :ok = Cluster.call(peer, Claims, :claim, [[1], peer])
    assert Cluster.call(peer, Claims, :owner_of, [1]) == nil
  end
end
