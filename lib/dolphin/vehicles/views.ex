defmodule Dolphin.Vehicles.Views do
  @moduledoc """
  The latest `Dolphin.Vehicles.View` of every vehicle this ground station
  knows, in one public ETS table that any process reads without asking
  anyone (`get/1`, `all/0`, `ids/0`).

  Each view has one writer, its owner: a vehicle's process in
  `Dolphin.Vehicles` puts a new view each time its state changes it, and a
  vehicle heard by another node can be put here the same way (`put/1` does
  not need a local vehicle process). Writing a view is also announcing it:

    1. the row is replaced;
    2. the transitions from the previous row (`Dolphin.Vehicles.View.transitions/2`)
       are emitted as `Dolphin.Events` events: `vehicle_discovered` once
       the type is known, `mode_changed`, `armed`, `disarmed`,
       `mission_item_reached`, `vehicle_lost`, `vehicle_reconnected`;
    3. `{:view, view}` is published on `Dolphin.PubSub` topic
       `{:vehicle, id}`, the vehicle's one topic (the engine's condition
       watchers follow it). After the events: whatever a reader of the view
       does about it (a mission ends on the disarm, and with it the script)
       comes after the event in every subscriber's mailbox, and an events
       file closed at the script's end has it;
    4. the same transitions' `{:vehicle_discovered, id}`, `{:vehicle_lost, id}`
       and `{:vehicle_reconnected, id}` are published on topic `:vehicles`,
       after the view (whoever hears of a loss finds the view saying so);
    5. `{:vehicle_changed, id}` is published on topic `:vehicles` when what a
       pick matches on, but the position, changed (`type`, `payloads`,
       `connected?`, a sensor heard for the first time, or a first view): the fleet serves its waiting picks
       again then, and on a slow tick for picks by region.

  Every source of views announces through here (a vehicle of this node, the
  cluster's mirror of another node's, `Dolphin.Fleet.FakeSource`), so those
  notices have one writer and always agree with the views. Deleting a view
  (`delete/1`, the vehicle is forgotten) publishes `{:vehicle_forgotten, id}`
  on `:vehicles`.

      Dolphin.Vehicles.Views.get(1)     # {:ok, %Dolphin.Vehicles.View{battery: 0.86, ...}}
      Dolphin.Vehicles.Views.ids()      # [1, 2, 3]

  ## When each vehicle was last heard

  A view changes when what it shows changes, not with every frame; when a
  vehicle's last frame came does. Each vehicle's process therefore also
  keeps that time (clock ms) in an `:atomics` cell of its own
  (`heard_cell/1`), a write per frame that costs next to nothing and wakes
  nobody; `last_heard_ms/1` reads it, for the cluster's station, which tells
  controllers how long ago each vehicle was heard.

  ## Which vehicle a path is

  Vehicles that share a system id are told apart by where they are heard
  (`Dolphin.Vehicles.Id`). A third table says which vehicle each path that
  is not its system id's first vehicle belongs to: `vehicle_on/2` is the id
  that a frame with a system id heard on a path is for (the system id itself
  unless `assign/4` gave the path to another vehicle), read by the router on
  every frame. An assignment outlives the vehicle: a vehicle forgotten and
  heard again on its path is discovered anew under the same name.

  The tables' owner is a small process under the application's supervisor,
  started before the vehicles' supervisor: the vehicles restart after it.
  """

  use GenServer

  alias Dolphin.{PubSub, Events}
  import Dolphin.Vehicles.Id, only: [is_id: 1]
  alias Dolphin.Vehicles.View

  @doc false
  # Started by its Dolphin.Instance, with the instance's names.
  @spec start_link(Dolphin.Instance.Names.t()) :: GenServer.on_start()
  def start_link(names), do: GenServer.start_link(__MODULE__, names, name: names.views)

  @doc """
  Writes a vehicle's view and announces it (see the module doc). Called by
  the view's owner only: two writers of one vehicle would interleave their
  transitions.
  """
  @spec put(View.t()) :: :ok
  def put(%View{id: id} = view) when is_id(id) do
    table = table()

    old =
      case :ets.lookup(table, id) do
        [{^id, old}] -> old
        [] -> nil
      end

    :ets.insert(table, {id, view})
    announce(old, view, true)
  end

  def put(other), do: raise(ArgumentError, "a view is a %Dolphin.Vehicles.View{} with a vehicle id, got: #{inspect(other)}")

  @doc "A vehicle's latest view."
  @spec get(Dolphin.Vehicles.Id.t()) :: {:ok, View.t()} | {:error, :unknown_vehicle}
  def get(id) do
    case :ets.lookup(table(), id) do
      [{^id, view}] -> {:ok, view}
      [] -> {:error, :unknown_vehicle}
    end
  end

  @doc "Every vehicle's latest view, by ascending id (system ids, then qualified names)."
  @spec all() :: [View.t()]
  def all, do: table() |> :ets.tab2list() |> Enum.sort() |> Enum.map(&elem(&1, 1))

  @doc "The ids of the vehicles with a view, ascending."
  @spec ids() :: [Dolphin.Vehicles.Id.t()]
  def ids, do: table() |> :ets.select([{{:"$1", :_}, [], [:"$1"]}]) |> Enum.sort()

  @doc """
  Forgets a vehicle's view (the vehicle is forgotten: a view put later is a
  discovery again), and says so with `{:vehicle_forgotten, id}` on
  `:vehicles` if there was one.
  """
  @spec delete(Dolphin.Vehicles.Id.t()) :: :ok
  def delete(id) do
    names = Dolphin.Instance.names()
    :ets.delete(names.heard, id)

    case :ets.take(names.views, id) do
      [] -> :ok
      [_] -> forgotten(id)
    end
  end

  @doc """
  The cell in which vehicle `id`'s owner writes when it last heard the
  vehicle (`heard/2`): the same cell for as long as the vehicle is not
  forgotten, so a restarted process goes on with it.
  """
  @spec heard_cell(Dolphin.Vehicles.Id.t()) :: :atomics.atomics_ref()
  def heard_cell(id) do
    # Slot 1: clock ms (any integer: the clock's origin is arbitrary); slot 2: 1 once written.
    heard = Dolphin.Instance.names().heard
    :ets.insert_new(heard, {id, :atomics.new(2, signed: true)})
    :ets.lookup_element(heard, id, 2)
  end

  @doc "Writes in a vehicle's cell that it was heard at `clock_ms`."
  @spec heard(:atomics.atomics_ref(), integer()) :: :ok
  def heard(cell, clock_ms) do
    :atomics.put(cell, 1, clock_ms)
    :atomics.put(cell, 2, 1)
  end

  @doc "When vehicle `id` was last heard (clock ms), or nil (never, or not a vehicle of this node)."
  @spec last_heard_ms(Dolphin.Vehicles.Id.t()) :: integer() | nil
  def last_heard_ms(id) do
    case :ets.lookup(Dolphin.Instance.names().heard, id) do
      [{^id, cell}] -> if :atomics.get(cell, 2) == 1, do: :atomics.get(cell, 1)
      [] -> nil
    end
  end

  # The notices on topic :vehicles that a view's transitions make.
  @notices [:vehicle_discovered, :vehicle_lost, :vehicle_reconnected]

  @doc false
  # Steps 2 to 5 of a write, for every owner of views (Dolphin.Fleet.FakeSource
  # keeps its own table): `events?` false keeps the telemetry quiet (a dry
  # run's stand-in vehicles), not the notices.
  @spec announce(View.t() | nil, View.t(), boolean()) :: :ok
  def announce(old, %View{id: id} = new, events?) do
    transitions = View.transitions(old, new)
    if events?, do: Enum.each(transitions, fn {event, meta} -> Events.emit(event, meta) end)
    PubSub.publish({:vehicle, id}, {:view, new})
    for {event, _} <- transitions, event in @notices, do: PubSub.publish(:vehicles, {event, id})

    # A sensor heard for the first time is one too (`pick(sensors: ...)`); its readings are not.
    if old == nil or old.type != new.type or old.airframe != new.airframe or old.payloads != new.payloads or old.connected? != new.connected? or
         map_size(old.sensors) != map_size(new.sensors),
       do: PubSub.publish(:vehicles, {:vehicle_changed, id})

    :ok
  end

  @doc """
  The id of the vehicle that a frame from system `sysid` heard on path `via`
  is for: `sysid` itself, unless the path was given to another vehicle with
  that system id (`assign/4`).
  """
  @spec vehicle_on(non_neg_integer(), term()) :: Dolphin.Vehicles.Id.t()
  def vehicle_on(sysid, via) do
    case :ets.lookup(paths(), {sysid, via}) do
      [{_, id, _uid}] -> id
      [] -> sysid
    end
  end

  @doc """
  Gives path `via` of system `sysid` to vehicle `id`, another vehicle with
  that system id, whose autopilot reports unique id `uid`: its frames are
  that vehicle's from now on.
  """
  @spec assign(non_neg_integer(), term(), Dolphin.Vehicles.Id.t(), non_neg_integer()) :: :ok
  def assign(sysid, via, id, uid) do
    :ets.insert(paths(), {{sysid, via}, id, uid})
    :ok
  end

  @doc "The vehicle that paths of system `sysid` with autopilot unique id `uid` were given to, or nil."
  @spec assigned(non_neg_integer(), non_neg_integer()) :: Dolphin.Vehicles.Id.t() | nil
  def assigned(sysid, uid) do
    case :ets.match(paths(), {{sysid, :_}, :"$1", uid}) do
      [[id] | _] -> id
      [] -> nil
    end
  end

  @doc """
  Whether a vehicle has id `id` already: a view, or paths given to it on a
  link still open (a fleet stopped with its links, such as `--sim`'s, leaves
  its names to the next).
  """
  @spec owns_name?(Dolphin.Vehicles.Id.t()) :: boolean()
  def owns_name?(id) do
    :ets.member(table(), id) or
      Enum.any?(:ets.match(paths(), {{:_, {:"$1", :_}}, id, :_}), fn [link] -> Registry.lookup(Dolphin.Instance.names().registry, {:link, link}) != [] end)
  end

  @doc false
  # The notice of a vehicle forgotten, for every owner of views.
  @spec forgotten(Dolphin.Vehicles.Id.t()) :: :ok
  def forgotten(id), do: PubSub.publish(:vehicles, {:vehicle_forgotten, id})

  @impl true
  def init(names) do
    for table <- [names.views, names.heard, names.paths], do: :ets.new(table, [:named_table, :public, :set, read_concurrency: true])
    {:ok, nil}
  end

  defp table, do: Dolphin.Instance.names().views
  defp paths, do: Dolphin.Instance.names().paths
end
