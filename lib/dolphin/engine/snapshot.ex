defmodule Dolphin.Engine.Snapshot do
  @moduledoc """
  What a condition reads, handed to it as its argument: a condition is a
  function of one argument, the snapshot (`Dolphin.Engine.Cond.new/2`), and
  reads vehicles and signals through the readers of this module.

      low = Dolphin.Engine.Cond.new(fn snap -> Dolphin.Engine.Snapshot.battery(snap, v) < 0.3 end, source: "battery(v) < 0.3")

  The script macros (`until(t, battery(v) < 0.3)`, `wait_for(poll(:go))`, ...)
  write conditions this way: they rewrite the readers of the language called
  in the condition's expression (`battery/1`, `position/1`, `altitude/1`,
  `relative_altitude/1`, `mode/1`, `armed?/1`, `connected?/1`,
  `mission_progress/1`, `poll/1,2`, and the sensors' `sensor/2`,
  `sensor_age/2`, `peak/3`, `peak_position/3` given the sensor declared)
  into the readers below.

  The node's `Dolphin.Engine.Watcher` builds the snapshot: the latest
  `Dolphin.Vehicles.View` of each vehicle the condition has read, and the
  signal tables it has read. A reader asked for a vehicle or a table that is
  not in the snapshot yet does not read it: it throws a request, which the
  watcher catches; the watcher subscribes to it, reads it, adds it to the
  condition's snapshot and evaluates the condition again. So what a
  condition reads is followed, with no hidden state: the snapshot is all the
  condition sees.

  A snapshot of `nil` means "no watcher": the readers then read the live data
  (the vehicle's source, `Dolphin.Vehicles.Views` for real vehicles; the
  signal table), as `Dolphin.Engine.Cond.evaluate/1` does.
  """

  alias Dolphin.Engine.{Context, Signals, Watcher}
  alias Dolphin.Fleet.VehicleSet
  alias Dolphin.Sensors.Sensor
  alias Dolphin.Vehicles.View

  defstruct vehicles: %{}, reads: MapSet.new(), signals: nil

  @typedoc "What a condition reads: a vehicle by system id, or a signal table."
  @type read :: {:vehicle, non_neg_integer()} | {:signals, Signals.table()}

  @typedoc """
  `vehicles`: views by system id (those of the watcher, a superset of what
  the condition may read); `reads`: what this condition has read, all it may
  read; `signals`: the script's signal table (`poll/2` reads it).
  """
  @type t :: %__MODULE__{vehicles: %{non_neg_integer() => View.t()}, reads: MapSet.t(read()), signals: Signals.table() | nil}

  # What a reader throws for something not in the snapshot (Dolphin.Engine.Cond.evaluate/2 catches it).
  @request :"$dolphin_read"

  @doc """
  The view of one vehicle (a one-vehicle set or a system id). Raises
  `ArgumentError` for a set of another size (`function` names the reader in
  the message); with no snapshot, also for an unknown vehicle.
  """
  @spec vehicle(t() | nil, VehicleSet.t() | non_neg_integer(), atom()) :: View.t()
  def vehicle(snapshot, ref, function \\ :vehicle)
  def vehicle(nil, ref, function), do: Watcher.vehicle(ref, function)

  def vehicle(%__MODULE__{reads: reads, vehicles: vehicles}, ref, function) do
    id = VehicleSet.one!(ref, function)

    case MapSet.member?(reads, {:vehicle, id}) do
      true -> Map.fetch!(vehicles, id)
      false -> throw({@request, {:vehicle, id}})
    end
  end

  @doc "A signal table the condition reads: the table itself, once it is in the snapshot."
  @spec signals(t() | nil, Signals.table()) :: Signals.table()
  def signals(nil, table), do: table

  def signals(%__MODULE__{reads: reads}, table) do
    case MapSet.member?(reads, {:signals, table}) do
      true -> table
      false -> throw({@request, {:signals, table}})
    end
  end

  @doc "Battery of a vehicle, `0.0..1.0` or `nil` (see `Dolphin.DSL.battery/1`)."
  @spec battery(t() | nil, VehicleSet.t() | non_neg_integer()) :: float() | nil
  def battery(snapshot, v), do: vehicle(snapshot, v, :battery).battery

  @doc "Position of a vehicle (see `Dolphin.DSL.position/1`)."
  @spec position(t() | nil, VehicleSet.t() | non_neg_integer()) :: Dolphin.Geo.Location.t() | nil
  def position(snapshot, v), do: vehicle(snapshot, v, :position).position

  @doc "Height of a vehicle above mean sea level (see `Dolphin.DSL.altitude/1`)."
  @spec altitude(t() | nil, VehicleSet.t() | non_neg_integer()) :: float() | nil
  def altitude(snapshot, v), do: with(%{h: h} <- vehicle(snapshot, v, :altitude).position, do: h)

  @doc "Height of a vehicle above its home (see `Dolphin.DSL.relative_altitude/1`)."
  @spec relative_altitude(t() | nil, VehicleSet.t() | non_neg_integer()) :: float() | nil
  def relative_altitude(snapshot, v), do: vehicle(snapshot, v, :relative_altitude).relative_altitude

  @doc "Flight mode of a vehicle (see `Dolphin.DSL.mode/1`)."
  @spec mode(t() | nil, VehicleSet.t() | non_neg_integer()) :: atom() | nil
  def mode(snapshot, v), do: vehicle(snapshot, v, :mode).mode

  @doc "Whether a vehicle is armed (see `Dolphin.DSL.armed?/1`)."
  @spec armed?(t() | nil, VehicleSet.t() | non_neg_integer()) :: boolean()
  def armed?(snapshot, v), do: vehicle(snapshot, v, :armed?).armed?

  @doc "Whether a vehicle is heard (see `Dolphin.DSL.connected?/1`)."
  @spec connected?(t() | nil, VehicleSet.t() | non_neg_integer()) :: boolean()
  def connected?(snapshot, v), do: vehicle(snapshot, v, :connected?).connected?

  @doc "Mission progress of a vehicle (see `Dolphin.DSL.mission_progress/1`)."
  @spec mission_progress(t() | nil, VehicleSet.t() | non_neg_integer()) :: {non_neg_integer(), non_neg_integer()} | nil
  def mission_progress(snapshot, v), do: vehicle(snapshot, v, :mission_progress).mission_progress

  @doc "A sensor's latest value on a vehicle, `nil` when not heard or stale (see `Dolphin.DSL.Sensors.sensor/2`)."
  @spec sensor(t() | nil, VehicleSet.t() | non_neg_integer(), Sensor.t()) :: float() | nil
  def sensor(snapshot, v, %Sensor{source: source, stale_after: stale_after} = sensor) do
    case vehicle(snapshot, v, :sensor).sensors do
      %{^source => %{stale: stale} = r} -> if stale_after in stale, do: nil, else: Dolphin.Sensors.value(sensor, r.value)
      _ -> nil
    end
  end

  @doc "Clock ms since a sensor's latest reading on a vehicle, `nil` before the first (see `Dolphin.DSL.Sensors.sensor_age/2`)."
  @spec sensor_age(t() | nil, VehicleSet.t() | non_neg_integer(), Sensor.t()) :: non_neg_integer() | nil
  def sensor_age(snapshot, v, %Sensor{source: source}) do
    case vehicle(snapshot, v, :sensor_age).sensors do
      %{^source => %{at: at}} -> max(Dolphin.Clock.now_ms() - at, 0)
      _ -> nil
    end
  end

  @doc "A sensor's highest value on a vehicle in the last `within` clock ms, `nil` when none (see `Dolphin.DSL.Sensors.peak/3`)."
  @spec peak(t() | nil, VehicleSet.t() | non_neg_integer(), Sensor.t(), pos_integer()) :: float() | nil
  def peak(snapshot, v, sensor, within) do
    with {value, _position} <- peak_reading(vehicle(snapshot, v, :peak), sensor, within), do: value
  end

  @doc "Where a vehicle was at `peak/4`'s reading, `nil` when none (see `Dolphin.DSL.Sensors.peak_position/3`)."
  @spec peak_position(t() | nil, VehicleSet.t() | non_neg_integer(), Sensor.t(), pos_integer()) :: Dolphin.Geo.Location.t() | nil
  def peak_position(snapshot, v, sensor, within) do
    with {_value, position} <- peak_reading(vehicle(snapshot, v, :peak_position), sensor, within), do: position
  end

  defp peak_reading(%View{sensors: sensors}, %Sensor{source: source} = sensor, within) when is_integer(within) and within > 0 do
    since = Dolphin.Clock.now_ms() - within

    case Map.get(sensors, source) do
      nil ->
        nil

      %{history: history} ->
        history
        |> Enum.take_while(fn {at, _, _} -> at >= since end)
        |> Enum.map(fn {_at, raw, position} -> {Dolphin.Sensors.value(sensor, raw), position} end)
        |> Enum.max_by(&elem(&1, 0), fn -> nil end)
    end
  end

  defp peak_reading(_view, %Sensor{name: name}, within),
    do: raise(ArgumentError, "peak(_, #{inspect(name)}, within: ...) takes a duration in ms (seconds(30)), got: #{inspect(within)}")

  @doc "Whether the script's signal `key` has a value (see `Dolphin.DSL.poll/1`)."
  @spec poll(t() | nil, term()) :: boolean()
  def poll(snapshot, key), do: Signals.poll(signals(snapshot, table(snapshot)), key)

  @doc "Whether the script's signal `key` has a value for which `fun` is truthy (see `Dolphin.DSL.poll/2`)."
  @spec poll(t() | nil, term(), (term() -> as_boolean(term()))) :: boolean()
  def poll(snapshot, key, fun), do: Signals.poll(signals(snapshot, table(snapshot)), key, fun)

  # The script's table: the snapshot's, or (live) the calling process's context's.
  defp table(%__MODULE__{signals: table}) when table != nil, do: table
  defp table(_), do: Context.current().signals
end
