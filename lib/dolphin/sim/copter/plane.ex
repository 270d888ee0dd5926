defmodule Dolphin.Sim.Copter.Plane do
  @moduledoc false
  # How a simulated ArduPlane moves (the model's `airframe: :plane`): it
  # cannot stand still. In the air it flies at its airspeed (AIRSPEED_CRUISE
  # 22 m/s, DO_CHANGE_SPEED), turning toward its target no faster than its
  # bank limit allows (a 45° bank: about 50 m of radius at 22 m/s), climbing
  # and sinking at its rates; every hold is a circle. Same navigation targets
  # as the copter's (Dolphin.Sim.Copter.Flight), flown as a plane flies them,
  # as ArduPlane SITL was seen doing (docs/ardupilot.md, "ArduPlane"):
  #
  #   {:climb, n, e, alt}      the take-off: straight ahead on its heading, climbing at its pitch
  #   {:goto, n, e, alt}       toward the point
  #   {:hold, n, e, alt}       circling the point at the loiter radius (LOITER, GUIDED, a stop)
  #   {:brake}                 what a copter's stop is: a plane circles where it is
  #   {:circle, n, e, alt, radius, turned, last}   a loiter item's circle
  #   {:land_at, n, e}         the landing: down the glide slope to the point, flare, roll out
  #   {:rtl, _}                home at RTL_ALTITUDE above it, circling there for ever

  import Dolphin.Sim.Copter, only: [ground: 1, home_alt: 1, home_ne: 1, distance_to: 3]

  alias Dolphin.Sim.Copter
  alias Dolphin.Sim.Copter.Flight

  alias Dolphin.Airframe.Plane, as: Airframe

  @g 9.81
  # LOITER, GUIDED and RTL circle at WP_LOITER_RAD (80 m), pulled out a little wider.
  @hold_radius 80.0
  # RTL_ALTITUDE (m above home).
  @rtl_alt 100.0
  # From touchdown to ArduPlane's auto-disarm: the land detector's ~9 s, then LAND_DISARMDELAY 20 s.
  @disarm_after_touchdown_ms 29_000
  @pi :math.pi()

  @doc false
  # The radius a loiter of `radius` (0: WP_LOITER_RAD) is flown at, its sign the direction.
  def flown_radius(radius), do: Airframe.flown_radius(Airframe.performance(), radius)

  @doc false
  # The take-off: along its heading, climbing to `alt`.
  @spec start_takeoff(Copter.t(), float()) :: Copter.t()
  def start_takeoff(c, alt) do
    h = c.heading * @pi / 180
    %{c | nav: {:climb, c.n + 10_000 * :math.cos(h), c.e + 10_000 * :math.sin(h), alt}, landed: :takeoff, ground_since: nil}
  end

  @doc false
  @spec fly(Copter.t(), float()) :: Copter.t()
  # Disarmed or with nothing to do on the ground: it stands.
  def fly(%{armed: false} = c, dt), do: if(c.alt > ground(c) + 0.5, do: glide(c, dt), else: still(c))
  def fly(%{nav: :idle} = c, _dt), do: still(c)

  # On the ground after a landing: it rolls to a stop.
  def fly(%{landed: :on_ground} = c, dt) do
    speed = max(ground_speed(c) - 4.0 * dt, 0.0)
    advance(%{c | vz: 0.0}, c.heading, speed, dt)
  end

  def fly(c, dt) do
    {c, {bearing, alt}} = target(c)
    speed = if c.landed == :takeoff, do: min(ground_speed(c) + 6.0 * dt, c.speed), else: c.speed
    heading = turn(c.heading, bearing, speed, dt)
    climb = climb_rate(c, alt, speed)
    c = %{c | vz: climb, alt: max(c.alt + climb * dt, ground(c))}
    advance(c, heading, speed, dt)
  end

  defp still(c), do: %{c | vn: 0.0, ve: 0.0, vz: 0.0}

  defp glide(c, dt), do: %{c | vz: -3.0, alt: max(c.alt - 3.0 * dt, ground(c))}

  defp advance(c, heading, speed, dt) do
    h = heading * @pi / 180
    {vn, ve} = {speed * :math.cos(h), speed * :math.sin(h)}
    %{c | heading: heading, vn: vn, ve: ve, n: c.n + vn * dt, e: c.e + ve * dt}
  end

  defp ground_speed(c), do: :math.sqrt(c.vn * c.vn + c.ve * c.ve)

  # The bearing (degrees) and height it steers for.
  defp target(c) do
    case c.nav do
      {:climb, n, e, alt} -> {c, {bearing(c, n, e), alt}}
      {:goto, n, e, alt} -> {c, {bearing(c, n, e), alt}}
      {:hold, n, e, alt} -> {c, {circle_bearing(c, n, e, @hold_radius), alt}}
      {:brake} -> {%{c | nav: {:hold, c.n, c.e, c.alt}}, {c.heading, c.alt}}
      {:descend} -> {%{c | nav: {:hold, c.n, c.e, c.alt}}, {c.heading, c.alt}}
      {:circle, n, e, alt, radius, turned, last} -> circle(c, n, e, alt, radius, turned, last)
      {:land_at, n, e} -> {%{c | landed: :landing}, {bearing(c, n, e), glide_alt(c, n, e)}}
      {:land, n, e} -> {%{c | landed: :landing}, {bearing(c, n, e), glide_alt(c, n, e)}}
      {:rtl, _} -> rtl(c)
      {:spool_up, _, next} -> {%{c | nav: next}, {c.heading, c.alt}}
    end
  end

  defp rtl(c) do
    {hn, he} = home_ne(c)
    alt = home_alt(c) + @rtl_alt
    {%{c | nav: {:circle, hn, he, alt, @hold_radius, 0.0, nil}}, {bearing(c, hn, he), alt}}
  end

  # Down the slope from where it is to the point, at the ground there.
  defp glide_alt(c, n, e) do
    d = distance_to(c, n, e)
    if d < 30, do: ground(c), else: ground(c) + (c.alt - ground(c)) * max(d - 30, 0) / d
  end

  defp circle(c, n, e, alt, radius, turned, last) do
    angle = :math.atan2(c.e - e, c.n - n)

    turned =
      case last do
        nil -> turned
        last -> turned + abs(Flight.wrap(angle - last))
      end

    {%{c | nav: {:circle, n, e, alt, radius, turned, angle}}, {circle_bearing(c, n, e, radius), alt}}
  end

  # Along the circle's tangent (clockwise for a positive radius), pulled toward its edge.
  defp circle_bearing(c, n, e, radius) do
    r = abs(radius)
    dn = c.n - n
    de = c.e - e
    d = :math.sqrt(dn * dn + de * de)

    if d > 2 * r do
      bearing(c, n, e)
    else
      out = :math.atan2(de, dn) * 180 / @pi
      direction = if radius < 0, do: -1, else: 1
      # On the circle, the tangent; inside, outward of it; outside, inward.
      correction = max(-60.0, min(60.0, (d - r) / r * 90.0))
      norm(out + direction * (90.0 + correction))
    end
  end

  defp bearing(c, n, e), do: norm(:math.atan2(e - c.e, n - c.n) * 180 / @pi)

  defp norm(deg), do: :math.fmod(:math.fmod(deg, 360.0) + 360.0, 360.0)

  # No faster than the bank limit: ω = g tan(bank) / v.
  defp turn(heading, bearing, speed, dt) do
    max_deg = @g * :math.tan(Airframe.bank_deg() * @pi / 180) / max(speed, 5.0) * 180 / @pi * dt
    diff = norm(bearing - heading + 180.0) - 180.0
    norm(heading + max(-max_deg, min(max_deg, diff)))
  end

  # Climbing at its pitch's rate (the take-off's, else 15°), sinking at most 4 m/s.
  defp climb_rate(c, alt, speed) do
    dz = alt - c.alt
    pitch = if c.item && c.item[:item], do: c.item.item.param1, else: 15.0
    up = Airframe.climb_rate(if(c.landed == :takeoff, do: pitch), speed)
    if dz > 0, do: min(dz, up), else: max(dz, -4.0)
  end

  @doc false
  # The land detector: flying once its take-off has climbed; landed on the
  # ground after a landing, disarmed by itself a while later (its NAV_LAND
  # never reported reached, the mission left on it).
  @spec touchdown(Copter.t()) :: Copter.t()
  def touchdown(c) do
    cond do
      c.landed == :takeoff and c.alt > ground(c) + 5.0 ->
        c

      c.landed == :landing and c.alt <= ground(c) + 0.05 ->
        %{c | landed: :on_ground, vz: 0.0, alt: ground(c), ground_since: c.time_ms}

      c.landed == :on_ground and c.armed and c.ground_since != nil and c.time_ms - c.ground_since >= @disarm_after_touchdown_ms ->
        %{Copter.text(c, 6, "Auto disarmed") | armed: false, ground_since: nil, nav: :idle}

      true ->
        c
    end
  end
end
