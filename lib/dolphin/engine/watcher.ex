defmodule Dolphin.Engine.Watcher do
  @moduledoc """
  The inputs of a task node's conditions: the engine side of "conditions are
  re-evaluated on every change of what they read".

  A watcher is a value held by a process: a node's (its conditions, and
  the vehicle of a platform task), or a run's conditions process (the
  conditions of its `until` nodes, which it evaluates in one place so that
  a change that trips many stops them all at once). It follows the
  vehicles and signal tables that the conditions read (and the vehicles a
  task flies when one of its conditions reads through functions nobody
  sees into: `follow/2`): the process holding it
  is subscribed to their topics on `Dolphin.PubSub`, and the watcher keeps
  the latest `Dolphin.Vehicles.View` of each vehicle, replaced whole by each
  one published (`update/2`).

  `evaluate/3` hands a condition its `Dolphin.Engine.Snapshot` as its
  argument: those views, and what this condition has read so far. A
  condition that reads a vehicle or a signal table not in its snapshot yet
  makes a request (`Dolphin.Engine.Cond.evaluate/2` returns `{:read, read}`):
  the watcher subscribes to it, then reads it from the source (no change is
  missed in between), adds it to the condition's reads and evaluates the
  condition again. Nothing goes through the process dictionary.

  What a condition has read stays followed while the condition is watched
  (a condition that stopped reading a vehicle is re-evaluated on its changes
  for nothing, never missed); once the condition is no longer watched
  (`forget/2`), what no other condition reads is let go.

  `vehicle/2` is the live reader: outside a condition's snapshot (code of an
  action, a helper function a condition calls), it reads the vehicle from
  the calling process's context's source.

      import Dolphin.Engine
      v = 1
      low = Dolphin.Engine.Cond.new(fn snap -> Dolphin.Engine.Snapshot.battery(snap, v) < 0.3 end, source: "battery(v) < 0.3")
      Dolphin.Engine.run(until(Dolphin.Engine.FakePlatform.task("survey", duration: :infinity), low))
  """

  alias Dolphin.Engine.{Cond, Context, Snapshot}
  alias Dolphin.Fleet.{Source, VehicleSet}
  alias Dolphin.PubSub
  alias Dolphin.Vehicles.View

  defstruct source: nil, signals_table: nil, vehicles: %{}, signals: MapSet.new(), reads: %{}, followed: MapSet.new()

  @typedoc """
  `vehicles`: the latest view of each vehicle followed (its keys are the
  vehicles subscribed to); `signals`: the tables subscribed to; `reads`: what
  each watched condition (by its node's key) has read; `followed`: vehicles
  followed whatever the conditions read; `signals_table`: the script's table,
  which `Dolphin.Engine.Snapshot.poll/2` reads.
  """
  @type t :: %__MODULE__{
          source: Source.t() | nil,
          signals_table: Dolphin.Engine.Signals.table() | nil,
          vehicles: %{non_neg_integer() => View.t()},
          signals: MapSet.t(),
          reads: %{term() => MapSet.t(Snapshot.read())},
          followed: MapSet.t()
        }

  @doc "A watcher of nothing yet, reading vehicles from `source`; `signals`: the script's signal table."
  @spec new(Source.t(), Dolphin.Engine.Signals.table() | nil) :: t()
  def new(source, signals \\ nil), do: %__MODULE__{source: source, signals_table: signals}

  @doc """
  Evaluates a condition (`Dolphin.Engine.Cond.evaluate/2`) on its snapshot,
  adding what it asks for (see the module doc) under `key`: from now on
  the calling process gets the events of it.
  """
  @spec evaluate(t(), term(), Cond.t()) :: {{:ok, boolean()} | {:error, Exception.t(), Exception.stacktrace()}, t()}
  def evaluate(%__MODULE__{} = w, key, %Cond{} = cond) do
    reads = Map.get(w.reads, key, MapSet.new())

    case Cond.evaluate(cond, %Snapshot{vehicles: w.vehicles, reads: reads, signals: w.signals_table}) do
      {:read, read} ->
        case add(w, read) do
          {:ok, w} -> evaluate(%{w | reads: Map.put(w.reads, key, MapSet.put(reads, read))}, key, cond)
          {:error, e} -> {{:error, e, []}, w}
        end

      result ->
        {result, w}
    end
  end

  @doc "Forgets what the condition of `key` read (it is no longer watched)."
  @spec forget(t(), term()) :: t()
  def forget(%__MODULE__{} = w, key) do
    case Map.has_key?(w.reads, key) do
      true -> sync(%{w | reads: Map.delete(w.reads, key)})
      false -> w
    end
  end

  @doc """
  Forgets what the condition of `key` read, letting go of `unread`: what
  the caller knows no other condition reads (`forget/2` works that out
  itself, in time that grows with all that is read). What is followed
  whatever the conditions read stays.
  """
  @spec forget(t(), term(), [Snapshot.read()]) :: t()
  def forget(%__MODULE__{} = w, key, unread) do
    Enum.reduce(unread, %{w | reads: Map.delete(w.reads, key)}, fn
      {:vehicle, id}, w ->
        if MapSet.member?(w.followed, id) or not Map.has_key?(w.vehicles, id) do
          w
        else
          Source.unsubscribe(id)
          %{w | vehicles: Map.delete(w.vehicles, id)}
        end

      {:signals, table}, w ->
        if MapSet.member?(w.signals, table), do: PubSub.unsubscribe({:dolphin_signals, table})
        %{w | signals: MapSet.delete(w.signals, table)}
    end)
  end

  @doc """
  Follows a vehicle whatever the conditions read (a platform task's, whose
  loss ends the task; those a task flies): subscribes, then reads it.
  Returns the read and the watcher.
  """
  @spec follow(t(), non_neg_integer()) :: {{:ok, View.t()} | {:error, :unknown_vehicle}, t()}
  def follow(%__MODULE__{} = w, id) do
    unless Map.has_key?(w.vehicles, id), do: Source.subscribe(id)

    case Source.vehicle(w.source, id) do
      {:ok, view} -> {{:ok, view}, %{w | vehicles: Map.put(w.vehicles, id, view), followed: MapSet.put(w.followed, id)}}
      {:error, _} = error -> {error, sync(w)}
    end
  end

  @doc "Takes in a view published for a vehicle followed (others are ignored)."
  @spec update(t(), View.t()) :: t()
  def update(%__MODULE__{vehicles: vehicles} = w, %View{id: id} = view) do
    if Map.has_key?(vehicles, id), do: %{w | vehicles: Map.put(vehicles, id, view)}, else: w
  end

  @doc "What the condition of `key` has read (while it is watched)."
  @spec reads(t(), term()) :: MapSet.t(Snapshot.read())
  def reads(%__MODULE__{reads: reads}, key), do: Map.get(reads, key, MapSet.new())

  @doc "Whether the condition of `key` has read `read` (a change of it may change the condition)."
  @spec reads?(t(), term(), Snapshot.read()) :: boolean()
  def reads?(%__MODULE__{reads: reads}, key, read) do
    case reads do
      %{^key => set} -> MapSet.member?(set, read)
      _ -> false
    end
  end

  # A read asked for: subscribed to first, then read (no change is missed in between).
  defp add(w, {:vehicle, id}) do
    case w.vehicles do
      %{^id => _} ->
        {:ok, w}

      _ ->
        Source.subscribe(id)

        case Source.vehicle(w.source, id) do
          {:ok, view} ->
            {:ok, %{w | vehicles: Map.put(w.vehicles, id, view)}}

          {:error, :unknown_vehicle} ->
            Source.unsubscribe(id)
            {:error, ArgumentError.exception("unknown vehicle #{inspect(id)}")}
        end
    end
  end

  defp add(w, {:signals, table}) do
    if MapSet.member?(w.signals, table) do
      {:ok, w}
    else
      PubSub.subscribe({:dolphin_signals, table})
      {:ok, %{w | signals: MapSet.put(w.signals, table)}}
    end
  end

  # Subscriptions to exactly what is read or followed.
  defp sync(w) do
    read = Enum.reduce(Map.values(w.reads), MapSet.new(), &MapSet.union/2)
    wanted = MapSet.union(w.followed, MapSet.new(for {:vehicle, id} <- read, do: id))
    {keep, drop} = Enum.split_with(w.vehicles, fn {id, _} -> MapSet.member?(wanted, id) end)
    Enum.each(drop, fn {id, _} -> Source.unsubscribe(id) end)
    tables = MapSet.new(for {:signals, table} <- read, do: table)
    Enum.each(MapSet.difference(w.signals, tables), &PubSub.unsubscribe({:dolphin_signals, &1}))
    %{w | vehicles: Map.new(keep), signals: MapSet.intersection(w.signals, tables)}
  end

  # --- the live reader ---

  @doc """
  The view of one vehicle (a one-vehicle set or a system id), read live
  from the calling process's context's source (for real vehicles,
  `Dolphin.Vehicles.Views`): what the script's readers (`battery/1`, ...)
  do outside a condition's expression. Raises `ArgumentError` for a set of
  another size or an unknown vehicle (`function` names the reader in the
  message).
  """
  @spec vehicle(VehicleSet.t() | non_neg_integer(), atom()) :: View.t()
  def vehicle(ref, function \\ :vehicle) do
    id = VehicleSet.one!(ref, function)

    case Source.vehicle(Context.source(Context.current()), id) do
      {:ok, v} -> v
      {:error, :unknown_vehicle} -> raise ArgumentError, "unknown vehicle #{inspect(id)}"
    end
  end

  @doc """
  The latest reading of `sensor` on a vehicle (a one-vehicle set or an id),
  read live as `vehicle/2` does, as a `Dolphin.Sensors.Detection`; nil when
  the vehicle is unknown or has none.
  """
  @spec detection(VehicleSet.t() | Dolphin.Vehicles.Id.t(), Dolphin.Sensors.Sensor.t()) :: Dolphin.Sensors.Detection.t() | nil
  def detection(ref, sensor) do
    case live_view(ref) do
      {:ok, view} -> Dolphin.Sensors.Detection.of(view, sensor)
      :error -> nil
    end
  end

  @doc """
  Every reading of `sensor` a vehicle keeps (`Dolphin.Sensors.Detection.kept/2`),
  read live as `vehicle/2` does; `[]` when the vehicle is unknown.
  """
  @spec detections(VehicleSet.t() | Dolphin.Vehicles.Id.t(), Dolphin.Sensors.Sensor.t()) :: [Dolphin.Sensors.Detection.t()]
  def detections(ref, sensor) do
    case live_view(ref) do
      {:ok, view} -> Dolphin.Sensors.Detection.kept(view, sensor)
      :error -> []
    end
  end

  # The view of one vehicle (a one-vehicle set or an id), read live from the
  # calling process's context's source; :error for another set or an unknown vehicle.
  defp live_view(ref) do
    with [id] <- VehicleSet.ids(VehicleSet.new(ref)),
         {:ok, view} <- Source.vehicle(Context.source(Context.current()), id) do
      {:ok, view}
    else
      _ -> :error
    end
  end
end
