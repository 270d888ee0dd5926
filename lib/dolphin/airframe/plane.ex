defmodule Dolphin.Airframe.Plane do
  @moduledoc """
  ArduPlane's fixed wings and quadplanes (`Dolphin.Airframe`; a quadplane
  is flown as a plane): it takes off climbing at the take-off's pitch, cannot
  stand still — a loiter circles at the given radius (flown about 1.2 times
  wider, never tighter than about 60 m at cruise) and a stop circles in
  LOITER — and lands through its landing sequence (DO_LAND_START, a
  waypoint 400 m out on the approach, in line with the way it comes, 28 m
  up — a 4° glide —, then NAV_LAND; RTL and a stopped mission jump to it),
  done once landed and disarmed (ArduPlane disarms by itself about 29 s
  after touchdown).

  Its figures are ArduPlane SITL's with default parameters: AIRSPEED_CRUISE
  22 m/s, AIRSPEED_MIN 10 and AIRSPEED_MAX 30 m/s, WP_RADIUS 50 m,
  WP_LOITER_RAD 80 m; turns limited to 45° of bank as its navigation flew
  them (a turn radius of v²/(g·tan 45°): 49 m at cruise); ~11.5 A in cruise,
  ~41 A climbing out, nothing on the ground.
  """

  use Dolphin.Airframe

  @g 9.81
  @bank_deg 45.0
  # WP_LOITER_RAD 80, flown at about 1.2 times its radius (97–98 m).
  @loiter_radius 80.0
  @flown_radius_factor 1.2
  # Not tighter than this at cruise speed (LOITER_TURNS of 40 m flew 62–74 m).
  @least_radius 60.0
  # Its landing's approach: in line 400 m out, on a 4° slope (28 m up).
  @approach {:approach, 400.0, 4.0}

  @impl true
  def takes_off?, do: true
  @impl true
  def lands?, do: true
  @impl true
  def landing_done, do: :disarmed
  @impl true
  def landing_commands, do: [{:mav_cmd_do_land_start, @approach}, @approach, :mav_cmd_nav_land]
  @impl true
  def hold_modes, do: [:loiter, :guided]
  @impl true
  def firmware, do: "ArduPlane"

  @impl true
  def performance do
    %{
      Dolphin.Airframe.base_performance()
      | cruise_speed: 22.0,
        climb_speed: 6.0,
        descent_speed: 4.0,
        circle_speed: 22.0,
        wp_radius: 50.0,
        hover_current: 11.5,
        min_speed: 10.0,
        max_speed: 30.0,
        landed_disarm_s: 29.0,
        hold_speed: 22.0,
        landing: :glide
    }
  end

  # Drag grows with the square of the speed; climbing out takes up to 3.5 times cruise.
  @impl true
  def current(p, speed, climb, true), do: p.hover_current * ((speed / p.cruise_speed) ** 2 + 2.5 * max(climb, 0) / p.climb_speed)
  def current(_p, _speed, _climb, false), do: 0.0

  @impl true
  def flown_radius(_p, radius) do
    r = if abs(radius) < 1, do: @loiter_radius, else: abs(radius)
    sign = if radius < 0, do: -1, else: 1
    sign * max(r * @flown_radius_factor, @least_radius)
  end

  @impl true
  def turn_radius(_p, speed), do: turn_radius(speed)

  # The take-off roll to cruise at about 6 m/s², then climbing at the pitch.
  @impl true
  def climb_out(p, pitch), do: {climb_rate(pitch, p.cruise_speed), p.cruise_speed * :math.cos(pitch_rad(pitch)), p.cruise_speed / 6.0}

  @doc "The radius (m) of a turn at `speed` (m/s) at the bank limit: v²/(g·tan bank)."
  @spec turn_radius(float()) :: float()
  def turn_radius(speed), do: speed * speed / (@g * :math.tan(bank_rad()))

  @doc "The bank limit of its turns (degrees)."
  @spec bank_deg() :: float()
  def bank_deg, do: @bank_deg

  @doc "How fast (m/s) it climbs at `pitch` degrees and `speed` m/s (15° when the pitch is none)."
  @spec climb_rate(number() | nil, float()) :: float()
  def climb_rate(pitch, speed), do: speed * :math.sin(pitch_rad(pitch))

  defp pitch_rad(pitch) when is_number(pitch) and pitch > 0, do: min(pitch, 90) * :math.pi() / 180
  defp pitch_rad(_none), do: 15.0 * :math.pi() / 180

  defp bank_rad, do: @bank_deg * :math.pi() / 180
end
