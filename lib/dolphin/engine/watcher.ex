defmodule Dolphin.Engine.Watcher do
  @moduledoc """
  The inputs of a task node's conditions: the engine side of "conditions are
  re-evaluated on every change of what they read".

  A watcher is a value held by the node's process. It follows exactly the
  vehicles and signal tables that the node's conditions read at their last
  evaluation (and the vehicle of a platform task: `follow/2`): the node's
  process is subscribed to their topics on `Dolphin.PubSub`, and the watcher
  keeps the latest `Dolphin.Vehicles.View` of each vehicle, replaced whole by
  each one published (`update/2`). `evaluate/3` hands a condition that
  snapshot; a vehicle read for the first time is subscribed to, then read
  from the source (no change is missed in between) and followed from then
  on. What no condition reads any more is let go.

  Readers of vehicle state (`vehicle/2`, through the script's `battery/1`,
  `position/1`, ...) and of signals (`Dolphin.Engine.Signals.poll/2`, ...)
  read from the snapshot of the evaluation under way; outside one, they read
  the source (for a vehicle) or the table (for a signal) directly.

      import Dolphin.Engine
      v = 1
      low = Dolphin.Engine.Cond.new(fn -> Dolphin.Engine.Watcher.vehicle(v).battery < 0.3 end, source: "battery(v) < 0.3")
      Dolphin.Engine.run(until(Dolphin.Engine.TestPlatform.task("survey", duration: :infinity), low))
  """

  alias Dolphin.Engine.{Cond, Context}
  alias Dolphin.Fleet.{Source, VehicleSet}
  alias Dolphin.PubSub
  alias Dolphin.Vehicles.View

  defstruct source: nil, vehicles: %{}, signals: MapSet.new(), reads: %{}, followed: MapSet.new()

  @typedoc """
  `vehicles`: the latest view of each vehicle followed (its keys are the
  vehicles subscribed to); `signals`: the tables subscribed to; `reads`: what
  each watched condition (by its node's key) read at its last evaluation;
  `followed`: vehicles followed whatever the conditions read.
  """
  @type t :: %__MODULE__{
          source: Source.t() | nil,
          vehicles: %{non_neg_integer() => View.t()},
          signals: MapSet.t(),
          reads: %{term() => MapSet.t()},
          followed: MapSet.t()
        }

  # The snapshot of the evaluation under way, for the readers: present only
  # while evaluate/3 runs.
  @scope :"$dolphin_evaluation"

  @doc "A watcher of nothing yet, reading vehicles from `source`."
  @spec new(Source.t()) :: t()
  def new(source), do: %__MODULE__{source: source}

  @doc """
  Evaluates a condition (`Dolphin.Engine.Cond.evaluate/1`) on the snapshot,
  and remembers what it read under `key` (replacing what it read before):
  from now on the calling process gets the events of exactly that.
  """
  @spec evaluate(t(), term(), Cond.t()) :: {{:ok, boolean()} | {:error, Exception.t(), Exception.stacktrace()}, t()}
  def evaluate(%__MODULE__{} = w, key, %Cond{} = cond) do
    Process.put(@scope, %{source: w.source, vehicles: w.vehicles, signals: w.signals, read: MapSet.new(), fresh: false})
    # Cond.evaluate/1 turns whatever the condition raises or throws into an error result.
    result = Cond.evaluate(cond)
    scope = Process.delete(@scope)

    # Most evaluations read what they read before: nothing to subscribe or let go.
    if not scope.fresh and Map.get(w.reads, key) == scope.read,
      do: {result, w},
      else: {result, sync(%{w | vehicles: scope.vehicles, signals: scope.signals, reads: Map.put(w.reads, key, scope.read)})}
  end

  @doc "Forgets what the condition of `key` read (it is no longer watched)."
  @spec forget(t(), term()) :: t()
  def forget(%__MODULE__{} = w, key), do: sync(%{w | reads: Map.delete(w.reads, key)})

  @doc """
  Follows a vehicle whatever the conditions read (a platform task's, whose
  loss ends the task): subscribes, then reads it. Returns the read and the
  watcher.
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

  # --- readers ---

  @doc """
  The view of one vehicle (a one-vehicle set or a system id): during a
  condition's evaluation, from its snapshot (the read is recorded); outside
  one, from the calling process's context's source. Raises `ArgumentError`
  for a set of another size or an unknown vehicle (`function` names the
  reader in the message).
  """
  @spec vehicle(VehicleSet.t() | non_neg_integer(), atom()) :: View.t()
  def vehicle(ref, function \\ :vehicle) do
    id = VehicleSet.one!(ref, function)

    case Process.get(@scope) do
      %{vehicles: %{^id => view}} = scope ->
        Process.put(@scope, %{scope | read: MapSet.put(scope.read, {:vehicle, id})})
        view

      %{} = scope ->
        # Subscribed before reading: no change is missed in between.
        Source.subscribe(id)

        view =
          try do
            fetch!(scope.source, id)
          rescue
            e ->
              Source.unsubscribe(id)
              reraise e, __STACKTRACE__
          end

        Process.put(@scope, %{scope | vehicles: Map.put(scope.vehicles, id, view), read: MapSet.put(scope.read, {:vehicle, id}), fresh: true})
        view

      nil ->
        fetch!(Context.source(Context.current()), id)
    end
  end

  defp fetch!(source, id) do
    case Source.vehicle(source, id) do
      {:ok, v} -> v
      {:error, :unknown_vehicle} -> raise ArgumentError, "unknown vehicle #{inspect(id)}"
    end
  end

  @doc false
  # Called by Dolphin.Engine.Signals as a signal table is read: during an
  # evaluation, the read is recorded (and the table subscribed to, once).
  @spec read_signals(term()) :: :ok
  def read_signals(table) do
    case Process.get(@scope) do
      nil ->
        :ok

      scope ->
        scope =
          if MapSet.member?(scope.signals, table),
            do: scope,
            else: %{scope | signals: subscribe_signals(scope.signals, table), fresh: true}

        Process.put(@scope, %{scope | read: MapSet.put(scope.read, {:signals, table})})
        :ok
    end
  end

  defp subscribe_signals(signals, table) do
    PubSub.subscribe({:dolphin_signals, table})
    MapSet.put(signals, table)
  end
end
