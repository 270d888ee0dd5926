defmodule Dolphin.Sim.Copter.Flight do
  @moduledoc false
  # How the simulated copter moves: a navigation target (`nav`) gives a
  # desired velocity, limited by the accelerations ArduCopter flew with, and
  # the land detector says when it has left or touched the ground. Positions
  # are metres on the copter's tangent plane (see Dolphin.Sim.Copter).
  #
  # Navigation targets:
  #   :idle                          on the ground, or nothing to do
  #   {:spool_up, until_ms, next}    motors spooling up before `next`
  #   {:climb | :goto | :hold, n, e, alt}
  #   {:brake}                       stopping, then holding where it stopped
  #   {:circle, n, e, alt, radius, turned, last_angle}
  #   {:land, n, e} / {:land_at, n, e} / {:descend}
  #   {:rtl, :climb | :return}

  import Dolphin.Sim.Copter, only: [ground: 1, home_alt: 1, home_ne: 1, in_air?: 1, resolve_alt: 2, ne: 3, distance_to: 3, surface: 1, flies?: 1]

  alias Dolphin.Sim.Copter
  alias Dolphin.Sim.Copter.{Mission, Modes}

  @pi :math.pi()

  # The motors spool up before the copter leaves the ground (its config's
  # `spool_up_ms`).
  @spec start_takeoff(Copter.t(), float()) :: Copter.t()
  def start_takeoff(%{config: %{airframe: :plane}} = c, alt), do: Dolphin.Sim.Copter.Plane.start_takeoff(c, alt)

  def start_takeoff(c, alt) do
    %{c | nav: {:spool_up, c.time_ms + c.config.spool_up_ms, {:climb, c.n, c.e, alt}}, landed: :takeoff, ground_since: nil}
  end

  # A GUIDED target: only in GUIDED and in the air.
  @spec guided_goto(Copter.t(), number(), number(), number() | {integer(), number()}) :: {:ok | :error, Copter.t()}
  def guided_goto(c, lat, lon, alt) do
    alt = resolve_alt(c, alt)

    if c.mode == :guided and in_air?(c) do
      {n, e} = ne(c, lat, lon)
      {:ok, %{c | nav: {:goto, n, e, alt}}}
    else
      {:error, c}
    end
  end

  # Desired velocity from the navigation target, then an acceleration limit:
  # that is what makes turns round and BRAKE overshoot.
  # Disarmed in the air (a forced disarm): it falls.
  @spec fly(Copter.t(), float()) :: Copter.t()
  # A plane flies as a plane (Dolphin.Sim.Copter.Plane).
  def fly(%{config: %{airframe: :plane}} = c, dt), do: Dolphin.Sim.Copter.Plane.fly(c, dt)

  # Disarmed, a copter in the air falls; a rover, boat or submarine (never "in the air" disarmed) stops where it is.
  def fly(%{armed: false} = c, dt) do
    if in_air?(c), do: %{c | vn: 0.0, ve: 0.0, vz: -8.0, alt: max(c.alt - 8.0 * dt, ground(c))}, else: %{c | vn: 0.0, ve: 0.0, vz: 0.0}
  end

  def fly(%{nav: :idle} = c, _dt), do: %{c | vn: 0.0, ve: 0.0, vz: 0.0}

  def fly(c, dt) do
    {c, {wn, we, wz}} = desired_velocity(c)
    a = if c.nav == {:brake}, do: c.config.brake_accel, else: c.config.accel
    {vn, ve} = accelerate({c.vn, c.ve}, {wn, we}, a * dt)
    max_dz = c.config.accel_z * dt
    vz = c.vz + max(-max_dz, min(max_dz, wz - c.vz))
    heading = if vn * vn + ve * ve > 1.0, do: :math.fmod(atan2_degrees(ve, vn) + 360, 360), else: c.heading
    {vz, alt} = vertical(c, vz, c.alt + vz * dt)
    %{c | vn: vn, ve: ve, vz: vz, n: c.n + vn * dt, e: c.e + ve * dt, alt: alt, heading: heading}
  end

  # A copter stays above its ground, a rover or boat at its own height, a
  # submarine at or below its surface.
  defp vertical(%{config: %{airframe: :copter}} = c, vz, alt), do: {vz, max(alt, ground(c))}
  defp vertical(%{config: %{airframe: :sub}} = c, vz, alt), do: {vz, min(alt, surface(c))}
  defp vertical(c, _vz, _alt), do: {0.0, c.alt}

  # Same order of operations as the flights recorded against ArduCopter.
  defp atan2_degrees(y, x), do: :math.atan2(y, x) * 180 / @pi

  # The horizontal velocity moved toward the wanted one by at most `max_dv`.
  @spec accelerate({float(), float()}, {float(), float()}, float()) :: {float(), float()}
  def accelerate({vn, ve}, {wn, we}, max_dv) do
    dn = wn - vn
    de = we - ve
    d = :math.sqrt(dn * dn + de * de)
    if d <= max_dv, do: {wn, we}, else: {vn + dn / d * max_dv, ve + de / d * max_dv}
  end

  defp desired_velocity(c) do
    case c.nav do
      {:spool_up, until_ms, next} ->
        if c.time_ms >= until_ms, do: {%{c | nav: next}, {0.0, 0.0, 0.0}}, else: {c, {0.0, 0.0, 0.0}}

      {:climb, n, e, alt} ->
        {c, toward(c, n, e, alt)}

      {:goto, n, e, alt} ->
        {c, toward(c, n, e, alt)}

      {:hold, n, e, alt} ->
        {c, toward(c, n, e, alt)}

      {:brake} ->
        if c.vn * c.vn + c.ve * c.ve < 0.04,
          do: {%{c | nav: {:hold, c.n, c.e, c.alt}}, {0.0, 0.0, 0.0}},
          else: {c, {0.0, 0.0, 0.0}}

      {:circle, n, e, alt, radius, turned, last} ->
        circle(c, n, e, alt, radius, turned, last)

      {:land, n, e} ->
        {c, land_velocity(c, n, e)}

      {:land_at, n, e} ->
        # Fly over the landing point first, then descend.
        if distance_to(c, n, e) <= c.config.wp_radius,
          do: {%{c | nav: {:land, n, e}, landed: :landing}, land_velocity(c, n, e)},
          else: {c, toward(c, n, e, c.alt)}

      {:descend} ->
        {c, {0.0, 0.0, -c.config.descent_speed}}

      {:rtl, :climb} ->
        target = max(c.alt, home_alt(c) + c.config.rtl_alt)
        if c.alt >= target - 0.5, do: {%{c | nav: {:rtl, :return}}, {0.0, 0.0, 0.0}}, else: {c, {0.0, 0.0, c.config.climb_speed}}

      {:rtl, :return} ->
        {hn, he} = home_ne(c)

        if distance_to(c, hn, he) <= c.config.wp_radius,
          do: {%{c | nav: {:land, hn, he}, landed: :landing}, {0.0, 0.0, 0.0}},
          else: {c, toward(c, hn, he, c.alt)}
    end
  end

  defp land_velocity(c, n, e) do
    {wn, we, _} = toward(c, n, e, c.alt)
    {wn, we, -c.config.descent_speed}
  end

  # Speed that lets the vehicle stop at the point: sqrt(2 a d), at most the cruise speed.
  @spec toward(Copter.t(), float(), float(), float()) :: {float(), float(), float()}
  def toward(c, n, e, alt) do
    dn = n - c.n
    de = e - c.e
    d = :math.sqrt(dn * dn + de * de)
    speed = min(c.speed, :math.sqrt(2 * c.config.accel * d) * 0.8)
    {wn, we} = if d < 0.05, do: {0.0, 0.0}, else: {dn / d * speed, de / d * speed}
    # Slowing down vertically in time to stop at the height.
    dz = alt - c.alt
    stop_z = :math.sqrt(2 * c.config.accel_z * abs(dz)) * 0.8
    wz = dz |> max(-c.config.descent_speed) |> min(c.config.climb_speed) |> max(-stop_z) |> min(stop_z)
    {wn, we, wz}
  end

  # Clockwise around the centre at the circle speed, pulled back onto the radius;
  # `turned` counts the radians flown around.
  # A radius under a metre: turn on the spot (timed by the caller).
  defp circle(c, n, e, alt, radius, _turned, _last) when abs(radius) < 1, do: {c, toward(c, n, e, alt)}

  defp circle(c, n, e, alt, radius, turned, last) do
    r = abs(radius)
    dn = c.n - n
    de = c.e - e
    d = :math.sqrt(dn * dn + de * de)
    angle = :math.atan2(de, dn)
    direction = if radius < 0, do: -1, else: 1
    # At most CIRCLE_RATE, and slow enough for the centripetal acceleration.
    speed = Enum.min([c.config.circle_speed, c.speed, r * c.config.circle_rate * :math.pi() / 180, 0.9 * :math.sqrt(c.config.accel * r)])

    {un, ue} = if d < 0.01, do: {1.0, 0.0}, else: {dn / d, de / d}
    # tangent clockwise (seen from above, north up): rotate the radial vector by +90°
    {tn, te} = {-ue * direction, un * direction}
    pull = max(-speed, min(speed, r - d))
    wn = tn * speed + un * pull
    we = te * speed + ue * pull
    {_, _, wz} = toward(c, c.n, c.e, alt)

    turned =
      case last do
        nil -> turned
        last -> turned + abs(wrap(angle - last))
      end

    {%{c | nav: {:circle, n, e, alt, radius, turned, angle}}, {wn, we, wz}}
  end

  @doc false
  # An angle difference (radians) brought into -π..π.
  def wrap(a) when a > @pi, do: a - 2 * @pi
  def wrap(a) when a < -@pi, do: a + 2 * @pi
  def wrap(a), do: a

  # The land detector: in the air past a metre of climb; landed when it
  # touches the ground going down.
  @spec touchdown(Copter.t()) :: Copter.t()
  def touchdown(%{config: %{airframe: :plane}} = c), do: Dolphin.Sim.Copter.Plane.touchdown(c)

  def touchdown(c) do
    cond do
      not flies?(c) ->
        c

      c.landed == :takeoff and c.alt > ground(c) + 1.0 ->
        %{c | landed: :in_air}

      c.landed in [:in_air, :landing] and c.alt <= ground(c) + 0.05 and c.vz <= 0 ->
        c = %{c | landed: :on_ground, vz: 0.0, vn: 0.0, ve: 0.0, alt: ground(c), nav: :idle}

        # The land detector disarms a copter that has landed (LAND, RTL, pilot
        # modes, a mission's landing), except on a mission's NAV_LAND followed
        # by a take-off, from which ArduCopter flies on armed.
        cond do
          not c.armed -> c
          Mission.takeoff_follows_landing?(c) -> Mission.item_reached(c)
          true -> Modes.disarm_now(c)
        end

      true ->
        c
    end
  end
end
