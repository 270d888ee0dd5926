defmodule Dolphin.Airframe.Sub do
  @moduledoc """
  ArduSub's submarines (`Dolphin.Airframe`): heights are depths (0 the
  surface, negative below; sent relative to its home at the surface, as
  ArduSub skips items in absolute altitude), no take-off; its landing
  surfaces where it is and is done once reported reached (it stays armed
  at the surface); a loiter and a stop hold position and depth (POSHOLD).
  Its figures are ArduSub SITL's: 1 m/s along a leg (WPNAV_SPEED 100),
  ~1.3 m/s up and down, ~8 A while armed whatever it does.
  """

  use Dolphin.Airframe

  @impl true
  def takes_off?, do: false
  @impl true
  def lands?, do: true
  @impl true
  def landing_done, do: :reached
  @impl true
  def firmware, do: "ArduSub"
  @impl true
  def heights, do: :depth
  @impl true
  def hold_modes, do: [:poshold, :guided]

  @impl true
  def performance do
    %{
      Dolphin.Airframe.base_performance()
      | cruise_speed: 1.0,
        accel: 0.12,
        brake_accel: 1.0,
        climb_speed: 1.27,
        descent_speed: 1.27,
        accel_z: 0.15,
        circle_speed: 1.0,
        circle_rate: 30.0,
        wp_radius: 1.0,
        hover_current: 8.0
    }
  end

  # Its thrusters hold it whatever it does.
  @impl true
  def current(p, _speed, _climb, _moving?), do: p.hover_current
end
