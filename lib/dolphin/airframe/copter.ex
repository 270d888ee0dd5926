defmodule Dolphin.Airframe.Copter do
  @moduledoc """
  ArduCopter's multirotors and helicopters (`Dolphin.Airframe`): it climbs
  straight up at a take-off (whatever the pitch), holds still at a loiter
  (LOITER_TURNS circles), lands with NAV_LAND and is done once landed and
  disarmed; a stop brakes (BRAKE). Its figures are the simulator's copter,
  held to ArduCopter SITL by the differential test: 10 m/s along a leg,
  2.5 m/s up, 1.5 m/s down, 30 A hovering, more moving and climbing.
  """

  use Dolphin.Airframe

  @impl true
  def takes_off?, do: true
  @impl true
  def lands?, do: true
  @impl true
  def landing_done, do: :disarmed
  @impl true
  def hold_modes, do: [:brake, :guided]
  @impl true
  def firmware, do: "ArduCopter"

  # WPNAV_SPEED up to 20 m/s; a take-off from the ground climbs at least 1 m
  # (ModeAuto::takeoff_start raises a lower target to it); the land
  # detector's disarm (DISARM_DELAY) is counted by the executor, not here.
  @impl true
  def performance, do: %{Dolphin.Airframe.base_performance() | max_speed: 20.0, least_take_off: 1.0}

  # Hovering costs the most; moving and climbing add to it (idle on the ground, armed: 15 %).
  @impl true
  def current(p, speed, climb, true), do: p.hover_current * (1.0 + 0.1 * speed / 10 + 0.2 * max(climb, 0) / 2.5)
  def current(p, _speed, _climb, false), do: p.hover_current * 0.15

  # ArduCopter's FENCE_ACTION: 1 RTL (else LAND), 2 LAND, 4 BRAKE (else LAND), 0 report only.
  @impl true
  def fence_action(:rtl), do: 1
  def fence_action(:land), do: 2
  def fence_action(:hold), do: 4
  def fence_action(:report), do: 0

  # Spooling up, then straight up.
  @impl true
  def climb_out(p, _pitch), do: {p.climb_speed, 0.0, 3.0}
end
