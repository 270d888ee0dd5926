defmodule Dolphin.Airframe.Ground do
  @moduledoc """
  ArduRover's rovers and boats (`Dolphin.Airframe`): no take-off and no
  landing (the language refuses both), heights ignored (it drives at its own),
  a loiter stops at the point (a boat holds within a couple of metres); a
  stop holds in LOITER (HOLD only cuts the throttle, and a boat drifts in
  it). Its figures are ArduRover SITL's: WP_SPEED 5 m/s, an effective turn
  radius of about 5 m, ~12 A at cruise and nothing standing still.
  """

  use Dolphin.Airframe

  @impl true
  def takes_off?, do: false
  @impl true
  def lands?, do: false
  @impl true
  def landing_done, do: :reached
  @impl true
  def firmware, do: "ArduRover"
  @impl true
  def heights, do: :own
  @impl true
  def hold_modes, do: [:loiter, :hold]

  # ArduRover's FENCE_ACTION: 1 RTL (or HOLD), 2 HOLD; no landing.
  @impl true
  def fence_action(:report), do: 0
  def fence_action(:rtl), do: 1
  def fence_action(:hold), do: 2
  def fence_action(:land), do: nil

  # The accelerations stand for how it slows to a waypoint and rounds a
  # corner: chosen so that the differential test's routes take the time
  # ArduRover took (test/dolphin/sitl/airframes_test.exs).
  @impl true
  def performance do
    %{Dolphin.Airframe.base_performance() | cruise_speed: 5.0, accel: 0.6, brake_accel: 3.0, circle_speed: 5.0, circle_rate: 30.0, wp_radius: 3.0, hover_current: 12.4}
  end

  # In proportion to its speed: nothing standing.
  @impl true
  def current(p, speed, _climb, _moving?), do: p.hover_current * speed / p.cruise_speed
end
