defmodule Dolphin.Fleet.MAVLinkSource do
  @moduledoc """
  The vehicles of `Dolphin.Vehicles` (real MAVLink vehicles, or the simulator's)
  as a `Dolphin.Fleet.Source`; its `arg` is unused.

  - type: the heartbeat's MAV_TYPE through `Dolphin.Fleet.Vehicle.class/1`;
  - payloads: the vehicle's components (a camera component gives `:camera`)
    plus configured ones: `config :dolphin, vehicle_payloads: %{2 => [:sidescan]}`;
  - battery, position (`Dolphin.Geo.Location`, height above mean sea level),
    relative altitude, mode, armed, landed state, mission progress
    `{reached, total}` from the vehicle's `Dolphin.Vehicles.State`.

  `Dolphin.Vehicles` already publishes the events the fleet needs.
  """

  @behaviour Dolphin.Fleet.Source

  alias Dolphin.Fleet.Vehicle

  @impl true
  def list(_arg), do: Dolphin.Vehicles.list()

  @impl true
  def vehicle(_arg, id) do
    case Dolphin.Vehicles.state(id) do
      {:ok, state} ->
        base = %Vehicle{id: id, connected?: not Map.get(state, :lost, false), payloads: configured(id)}
        {:ok, apply_changes(nil, base, Map.take(Map.from_struct(state), [:type, :components, :battery, :position, :mode, :armed, :mission, :landed]))}

      {:error, :unknown_vehicle} ->
        {:error, :unknown_vehicle}
    end
  end

  @impl true
  def apply_changes(_arg, %Vehicle{} = v, changes), do: Enum.reduce(changes, v, &change/2)

  defp change({:type, type}, v), do: %{v | type: Vehicle.class(type)}

  defp change({:components, components}, v),
    do: %{v | payloads: Enum.sort(Enum.uniq(Enum.to_list(components) ++ configured(v.id)))}

  defp change({:battery, battery}, v), do: %{v | battery: battery}
  defp change({:position, nil}, v), do: %{v | position: nil, relative_altitude: nil}

  defp change({:position, p}, v),
    do: %{v | position: Dolphin.Geo.Location.new(p.lat, p.lon, p.alt), relative_altitude: p.relative_alt * 1.0}

  defp change({:mode, mode}, v), do: %{v | mode: mode}
  defp change({:armed, armed}, v), do: %{v | armed?: armed}
  defp change({:landed, landed}, v), do: %{v | landed: landed}
  # No MISSION_CURRENT yet: the total is not known, nor is the progress.
  defp change({:mission, %{total: nil}}, v), do: %{v | mission_progress: nil}
  defp change({:mission, m}, v), do: %{v | mission_progress: {m.reached || 0, m.total}}
  defp change({:lost, lost}, v), do: %{v | connected?: not lost}
  defp change({:link_quality, q}, v), do: %{v | link: Map.take(q, [:rtt_ms, :loss_in, :loss_out])}
  defp change(_other, v), do: v

  defp configured(id), do: Application.get_env(:dolphin, :vehicle_payloads, %{}) |> Map.get(id, []) |> List.wrap()

  @impl true
  def set_timeout(_arg, id, ms), do: Dolphin.Vehicles.set_timeout(id, ms)

  @impl true
  def send_message(_arg, id, message), do: Dolphin.Vehicles.send_message(id, message)
end
