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
    case Enum.filter(ids, fn id -> owner_of(id) not in [nil, owner] end) do
      [] ->
        for id <- ids, owner_of(id) == nil do
          {:ok, holder} = Task.Supervisor.start_child({Dolphin.Fleet.ClaimHolders, node(owner)}, __MODULE__, :hold, [id, owner])
          :yes = :global.register_name(name(id), holder, &__MODULE__.resolve/3)
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
  def hold(id, owner) do
    ref = Process.monitor(owner)
    hold(id, owner, ref)
  end

  defp hold(id, owner, ref) do
    receive do
      {:"$gen_call", from, :owner} ->
        GenServer.reply(from, owner)
        hold(id, owner, ref)

      {:DOWN, ^ref, :process, _, _} ->
        :global.unregister_name(name(id))
        released([id])

      :release ->
        :ok

      :dropped ->
        :ok
    end
  end

  @doc "Of `ids`, those claimed by an owner other than `owner` (for a pick to skip)."
  @spec taken([non_neg_integer()], pid()) :: [non_neg_integer()]
  def taken(ids, owner) do
    if Node.alive?(), do: Enum.filter(ids, fn id -> owner_of(id) not in [nil, owner] end), else: []
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
