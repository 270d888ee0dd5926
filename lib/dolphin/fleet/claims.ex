defmodule Dolphin.Fleet.Claims do
  @moduledoc """
  Cluster-wide claims on vehicles, so that a pick never gives one vehicle
  to two scripts running on two nodes of a cluster of ground stations
  (`Dolphin.Cluster`), even when both pick at the same moment.

      :ok = Dolphin.Fleet.Claims.claim([1, 2], self())
      {:error, {:taken, [2]}} = Dolphin.Fleet.Claims.claim([2, 3], other)   # on any node
      :ok = Dolphin.Fleet.Claims.release([1, 2])

  A claim is a `:global` name `{Dolphin.Fleet.Claims, id}`, registered to a
  small holder process on the owner's node that monitors the owner (under
  that node's `Dolphin.Fleet.ClaimHolders`, a `Task.Supervisor`). `claim/2` takes a cluster-wide lock (`:global.trans/4`), checks every
  id, and registers them all or none: two claims of overlapping sets are
  served one after the other, and the second is told which ids are taken.
  A claim whose owner ends is gone by itself, and watching fleets are told
  as for a release; one whose node goes down is gone too (`:global` drops
  the names of a node that left; fleets see the `:nodedown`).

  Fleets hear of released claims by joining the `:fleets` group (`watch/0`):
  `release/1` sends each member `{Dolphin.Fleet.Claims, :released, ids}`, and
  a waiting pick can be served again.

  One vehicle may have different ids on different nodes: a controller
  names a second station's vehicle of an id it already has `"ID@NODE"`
  (`Dolphin.Cluster.Mirror`), where that station and another controller
  call it by its id. So a claim also holds the vehicle as each station that
  hears it calls it (`{node, id there}`; a vehicle of this node's own: this
  node and its id): a pick of one vehicle under two names is refused on
  either node, whichever name it uses. Those are taken when the claim is
  made (a station that begins to hear the vehicle later is not in it) and
  let go with the claim.

  After a netsplit, both sides may have claimed one vehicle. When they meet
  again, `:global` keeps one claim (the one whose owner's node sorts first)
  and drops the other *without killing its owner*, and the double claim is
  reported: a `claim_conflict` event and an error in the log, naming both
  owners' nodes. The operator decides; nothing is stopped behind their back.

  Claims are made only on a distributed node (started with `--sname` or
  `--name`: meant to be part of a cluster, even while it is cut off from the
  others); on a node without distribution `claim/2` and `release/1` return
  `:ok` at once and a single ground station behaves and performs as before.
  """

  require Logger

  @lock :dolphin_fleet_claims

  @doc """
  Claims `ids` for `owner` (a pid, usually the fleet's or the script's
  process): all of them, or none and `{:error, {:taken, ids_taken}}`.
  Ids already claimed by `owner` itself count as free.
  """
  @spec claim([non_neg_integer()], pid()) :: :ok | {:error, {:taken, [non_neg_integer()]}}
  def claim(ids, owner) when is_list(ids) and is_pid(owner) do
    if Node.alive?() do
      # Names registered by a node that has just connected reach this one
      # only once :global has synchronized with it.
      :ok = :global.sync()
      :global.trans({@lock, self()}, fn -> claim_locked(Enum.uniq(ids), owner) end, [node() | Node.list()])
    else
      :ok
    end
  end

  defp claim_locked(ids, owner) do
    heard = Map.new(ids, &{&1, heard_as(&1)})

    case Enum.filter(ids, fn id -> Enum.any?([id | Enum.map(heard[id], &{:heard, &1})], &(owner_of(&1) not in [nil, owner])) end) do
      [] ->
        for id <- ids, owner_of(id) == nil do
          {:ok, holder} = Task.Supervisor.start_child({Dolphin.Fleet.ClaimHolders, node(owner)}, __MODULE__, :hold, [id, owner])
          :yes = :global.register_name(name(id), holder, &__MODULE__.resolve/3)

          aliases =
            for as <- heard[id], key = {:heard, as}, owner_of(key) == nil do
              {:ok, alias_holder} = Task.Supervisor.start_child({Dolphin.Fleet.ClaimHolders, node(owner)}, __MODULE__, :hold, [key, owner])
              :yes = :global.register_name(name(key), alias_holder, &__MODULE__.resolve/3)
              {key, alias_holder}
            end

          send(holder, {:aliases, aliases})
        end

        :ok

      taken ->
        {:error, {:taken, Enum.sort(taken)}}
    end
  end

  @doc "Releases the claims on `ids` (whoever holds them) and tells every watching fleet."
  @spec release([non_neg_integer()]) :: :ok
  def release(ids) when is_list(ids) do
    if Node.alive?() do
      :global.trans(
        {@lock, self()},
        fn ->
          for id <- ids, holder = :global.whereis_name(name(id)), holder != :undefined do
            # (Only those it still holds: after a netsplit another's may have the name.)
            for {key, alias_holder} <- aliases_of(holder), :global.whereis_name(name(key)) == alias_holder, do: :global.unregister_name(name(key))
            :global.unregister_name(name(id))
            send(holder, :release)
          end
        end,
        [node() | Node.list()]
      )

      released(ids)
    end

    :ok
  end

  defp released(ids) do
    for fleet <- :pg.get_members(Dolphin.Cluster.scope(), :fleets), fleet != self(),
        do: send(fleet, {__MODULE__, :released, ids})
  end

  defp aliases_of(holder) do
    GenServer.call(holder, :aliases, 5_000)
  catch
    :exit, _ -> []
  end

  # The vehicle as each station that hears it calls it: `{node, id there}`.
  defp heard_as(id) do
    cond do
      Dolphin.Vehicles.whereis_local(id) -> [{node(), id}]
      Process.whereis(Dolphin.Cluster.Mirror) -> Dolphin.Cluster.Mirror.heard_as(id)
      true -> []
    end
  end

  @doc "The owner of the claim on `id`, or nil."
  @spec owner_of(non_neg_integer()) :: pid() | nil
  def owner_of(id) do
    case :global.whereis_name(name(id)) do
      :undefined -> nil
      holder -> GenServer.call(holder, :owner, 5_000)
    end
  catch
    # The claim ended between the look-up and the question.
    :exit, _ -> nil
  end

  @doc false
  # A claim's holder: the process its global name is registered to, on the
  # owner's node (:global allows one name per process, and an owner may
  # claim several vehicles). It ends with the claim: released, its owner
  # gone (then fleets are told), or dropped after a netsplit.
  # (A claim's aliases, the vehicle as its stations call it, are held by
  # processes of their own, `{key, holder}`, told to the claim's holder: let
  # go with the claim.)
  def hold(key, owner) do
    ref = Process.monitor(owner)
    hold(key, owner, ref, [])
  end

  defp hold(key, owner, ref, aliases) do
    receive do
      {:"$gen_call", from, :owner} ->
        GenServer.reply(from, owner)
        hold(key, owner, ref, aliases)

      {:"$gen_call", from, :aliases} ->
        GenServer.reply(from, aliases)
        hold(key, owner, ref, aliases)

      {:aliases, more} ->
        hold(key, owner, ref, aliases ++ more)

      {:DOWN, ^ref, :process, _, _} ->
        # (Each alias's holder sees the owner go too.)
        :global.unregister_name(name(key))
        unless match?({:heard, _}, key), do: released([key])

      :release ->
        Enum.each(aliases, fn {_key, holder} -> send(holder, :release) end)

      :dropped ->
        :ok
    end
  end

  @doc "Of `ids`, those claimed by an owner other than `owner` (for a pick to skip)."
  @spec taken([non_neg_integer()], pid()) :: [non_neg_integer()]
  def taken(ids, owner) do
    if Node.alive?(), do: Enum.filter(ids, fn id -> Enum.any?([id | Enum.map(heard_as(id), &{:heard, &1})], &(owner_of(&1) not in [nil, owner])) end), else: []
  end

  @doc """
  Makes the calling process (a fleet) hear of released claims from every
  node: `{Dolphin.Fleet.Claims, :released, ids}` messages.
  """
  @spec watch() :: :ok
  def watch, do: :pg.join(Dolphin.Cluster.scope(), :fleets, self())

  @doc false
  # :global's resolver when a healed netsplit finds one claim on both sides:
  # keep one, drop the other's registration without killing its owner, and
  # report the double claim.
  def resolve({__MODULE__, id}, holder1, holder2) do
    [keep, drop] = Enum.sort_by([holder1, holder2], &{node(&1), &1})
    send(drop, :dropped)
    report(id, keep, drop)
    keep
  end

  defp report({:heard, {node, id}}, keep, drop), do: report("#{id}@#{node}", keep, drop)

  defp report(id, keep, drop) do
    Logger.error("vehicle #{id} was claimed on both sides of a netsplit, by an owner on #{node(keep)} and one on #{node(drop)}: the claim of #{node(keep)} is kept, the other dropped; nobody was stopped")
    # Told on the node where :global resolves, as every event is.
    Dolphin.Events.emit(:claim_conflict, %{vehicle: id, kept: node(keep), dropped: node(drop)})
  catch
    # A report that cannot be made must not keep :global from resolving.
    _, _ -> :ok
  end

  defp name(id), do: {__MODULE__, id}
end
