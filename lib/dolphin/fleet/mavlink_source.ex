defmodule Dolphin.Fleet.MAVLinkSource do
  @moduledoc """
  The vehicles of `Dolphin.Vehicles` (real MAVLink vehicles, or the simulator's)
  as a `Dolphin.Fleet.Source`; its `arg` is unused.

  Each vehicle's process publishes its `Dolphin.Vehicles.View` (see
  `Dolphin.Vehicles.View.of/3`): the heartbeat's MAV_TYPE as a class and an
  airframe, payloads from its components (a camera component gives
  `:camera`) plus those given to it (`Dolphin.Vehicles.put_payloads/2`, a
  fleet file's: `--fleet FILE`) and configured ones (`config :dolphin,
  vehicle_payloads: %{2 => [:sidescan]}`), battery,
  position, relative altitude, mode, armed, landed state, mission progress,
  link figures, read from `Dolphin.Vehicles.Views`, which already publishes
  and emits what a source must (including vehicles heard by other nodes
  and put there).
  """

  @behaviour Dolphin.Fleet.Source

  @impl true
  def list(_arg), do: Dolphin.Vehicles.list()

  @impl true
  def vehicle(_arg, id), do: Dolphin.Vehicles.view(id)

  @impl true
  def views(_arg), do: Dolphin.Vehicles.Views.all()

  @impl true
  def set_timeout(_arg, id, ms), do: Dolphin.Vehicles.set_timeout(id, ms)

  @impl true
  def send_message(_arg, id, message), do: Dolphin.Vehicles.send_message(id, message)
end
