defmodule Dolphin.Sensors.Detection do
  @moduledoc """
  A sensor reading that passed what a script waited for: which vehicle read
  it, the value, where the vehicle was and when (clock ms). A met condition
  that reads a sensor says one per vehicle and sensor it read, and
  `on_sensor` hands one to its `then:` function; each is also a
  `sensor_threshold` event (`event_fields/1`).
  """

  alias Dolphin.Sensors
  alias Dolphin.Sensors.Sensor

  @enforce_keys [:vehicle, :sensor]
  defstruct vehicle: nil, sensor: nil, value: nil, unit: nil, position: nil, at_ms: nil

  @type t :: %__MODULE__{
          vehicle: Dolphin.Vehicles.Id.t(),
          sensor: atom(),
          value: float() | nil,
          unit: atom() | nil,
          position: Dolphin.Geo.Location.t() | nil,
          at_ms: integer() | nil
        }

  @doc """
  The detection of `sensor` on the vehicle of `view` (a
  `Dolphin.Vehicles.View`): its latest reading, or `nil` when it has none.
  """
  @spec of(Dolphin.Vehicles.View.t(), Sensor.t()) :: t() | nil
  def of(%{id: id, sensors: readings}, %Sensor{source: source} = sensor) do
    case Map.get(readings, source) do
      nil -> nil
      r -> %__MODULE__{vehicle: id, sensor: sensor.name, value: Sensors.value(sensor, r.value), unit: sensor.unit, position: r.position, at_ms: r.at}
    end
  end

  @doc """
  Every reading of `sensor` a vehicle's view keeps (the last `keep` ms of
  them, `Dolphin.Sensors.Readings`), newest first, each as a detection.
  """
  @spec kept(%{id: term(), sensors: map()}, Sensor.t()) :: [t()]
  def kept(%{id: id, sensors: readings}, %Sensor{source: source} = sensor) do
    case Map.get(readings, source) do
      %{history: history} -> for {at, raw, position} <- history, do: %__MODULE__{vehicle: id, sensor: sensor.name, value: Sensors.value(sensor, raw), unit: sensor.unit, position: position, at_ms: at}
      _ -> []
    end
  end

  @doc """
  The fields of its `sensor_threshold` event (`Dolphin.Events`), given the
  condition's text and the vehicle sent to look (nil: none).

      iex> d = %Dolphin.Sensors.Detection{vehicle: 2, sensor: :smoke, value: 0.61, position: Dolphin.Geo.location(40.4451, -7.376, 860)}
      iex> Dolphin.Sensors.Detection.event_fields(d, "smoke above 0.4", nil)
      %{vehicle: 2, sensor: :smoke, value: 0.61, unit: nil, lat: 40.4451, lon: -7.376, h: 860.0, condition: "smoke above 0.4", sent: nil}
  """
  @spec event_fields(t(), String.t(), Dolphin.Vehicles.Id.t() | nil) :: map()
  def event_fields(%__MODULE__{} = d, condition, sent) do
    {lat, lon, h} = if d.position, do: {d.position.lat, d.position.lon, d.position.h}, else: {nil, nil, nil}
    %{vehicle: d.vehicle, sensor: d.sensor, value: d.value && Float.round(d.value * 1.0, 4), unit: d.unit, lat: lat, lon: lon, h: h, condition: condition, sent: sent}
  end
end
