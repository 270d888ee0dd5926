defmodule Dolphin.Airframe do
  @moduledoc """
  What differs between the kinds of vehicle ArduPilot flies, written once:
  a behaviour with one module per family — `Dolphin.Airframe.Copter`
  (ArduCopter), `Dolphin.Airframe.Plane` (ArduPlane's planes and
  quadplanes), `Dolphin.Airframe.Ground` (ArduRover's rovers and boats) and
  `Dolphin.Airframe.Sub` (ArduSub) — chosen from a vehicle's airframe
  (`Dolphin.Vehicles.View.airframe/2`, from its HEARTBEAT) with `of/1`.

  The mission compiler (`Dolphin.Mission.to_items/2`: what a landing is,
  whether heights are depths), the language's refusals
  (`Dolphin.Mission.airframes/1`), the executor (whether the vehicle leaves
  the ground), a stop (`Dolphin.Vehicles.Manoeuvres.hold_modes/1`), the
  pre-flight check (speeds, turns, energy and time) and the simulator
  (`Dolphin.Sim`: the same speeds, the same current draw) all ask these
  modules; none of them keeps a list of airframes of its own.

  The figures (`t:performance/0`) are what each firmware's SITL was seen
  doing with its default parameters (`docs/ardupilot.md`, "Other
  airframes"), which the simulator's differential tests hold it to.

      iex> Dolphin.Airframe.of(:boat)
      Dolphin.Airframe.Ground
      iex> Dolphin.Airframe.takes_off()
      [:copter, :plane, :quadplane]
      iex> Dolphin.Airframe.lands()
      [:copter, :plane, :quadplane, :sub]
      iex> Dolphin.Airframe.Plane.turn_radius(22.0) |> round()
      49
  """

  @typedoc "An airframe, as `pick(airframe: ...)` names it."
  @type t :: :copter | :plane | :quadplane | :rover | :boat | :sub

  @all [:copter, :plane, :quadplane, :rover, :boat, :sub]

  @typedoc """
  How an airframe moves and what it draws, as its firmware's SITL flew with
  default parameters:

    * `cruise_speed`, `climb_speed`, `descent_speed` (m/s): along a leg, up
      and down (a plane's climb is its take-off pitch's, see `climb_rate/3`);
    * `circle_speed` (m/s) round a loiter circle, `circle_rate` (°/s);
    * `accel`, `brake_accel`, `accel_z` (m/s²): speeding up along a leg and
      rounding its end, stopping, changing vertical speed;
    * `wp_radius` (m): how close a waypoint counts as reached;
    * `hover_current` (A): the current `current/3` scales — a copter's
      hover, a plane's or rover's cruise, a submarine's thrusters;
    * `capacity_mah`: the pack;
    * `min_speed`, `max_speed` (m/s): the speeds a mission may set (a
      plane's AIRSPEED_MIN and AIRSPEED_MAX; nil where nothing is known);
    * `max_loiter_radius` (m): the largest radius the firmware keeps;
    * `least_take_off` (m): the least a take-off from the ground climbs;
    * `landed_disarm_s`: from touchdown to the firmware's own disarm;
    * `hold_speed` (m/s): how fast it moves while it holds (a plane circles);
    * `landing`: `:vertical` (across at its height, then straight down —
      or up, a submarine surfacing) or `:glide` (down a slope to the point).
  """
  @type performance :: %{
          cruise_speed: float(),
          climb_speed: float(),
          descent_speed: float(),
          circle_speed: float(),
          circle_rate: float(),
          accel: float(),
          brake_accel: float(),
          accel_z: float(),
          wp_radius: float(),
          hover_current: float(),
          capacity_mah: float(),
          min_speed: float() | nil,
          max_speed: float() | nil,
          max_loiter_radius: float(),
          least_take_off: float(),
          landed_disarm_s: float(),
          hold_speed: float(),
          landing: :vertical | :glide
        }

  @typedoc "What an item's height means: metres above sea level, the vehicle's own height (ignored), or a depth below the surface."
  @type heights :: :altitude | :own | :depth

  @doc "Whether it takes off and flies (NAV_TAKEOFF, a vehicle in the air); else it starts and ends where it is."
  @callback takes_off?() :: boolean()

  @doc "Whether it has a landing: NAV_LAND and RTL end with it down (a submarine's surfaces)."
  @callback lands?() :: boolean()

  @doc "When a mission ending in a landing is done: once landed and disarmed, or once its landing item is reported reached."
  @callback landing_done() :: :disarmed | :reached

  @doc """
  What a landing at a point is made of, in order: MAV_CMD names at the
  point; `{:approach, metres, slope_deg}`, a waypoint that far before it on
  the way in, high enough to glide down at that slope; `{name, {:approach,
  ...}}`, a command at that waypoint.
  """
  @callback landing_commands() :: [atom() | {:approach, float(), float()} | {atom(), {:approach, float(), float()}}]

  @callback heights() :: heights()

  @doc "The firmware that flies it, as its messages are named."
  @callback firmware() :: String.t()

  @doc """
  Its firmware's FENCE_ACTION for a fence's `on_breach` (`Dolphin.Fence`),
  or nil when it has none such.
  """
  @callback fence_action(:rtl | :land | :hold | :report) :: non_neg_integer() | nil

  @doc "The modes that hold it where it is, the first the one a stop asks for."
  @callback hold_modes() :: [atom()]

  @callback performance() :: performance()

  @doc "The current (A) it draws at a ground speed and climb rate (m/s), in the air (or moving) or not."
  @callback current(performance(), speed :: float(), climb :: float(), airborne? :: boolean()) :: float()

  @doc "The radius (m) a loiter of `radius` (0: the firmware's default) is flown at, its sign the direction."
  @callback flown_radius(performance(), radius :: number()) :: float()

  @doc "The smallest radius (m) it can turn at `speed` (0 for one that turns on the spot)."
  @callback turn_radius(performance(), speed :: float()) :: float()

  @doc """
  How it climbs out from the ground at a take-off of `pitch` degrees:
  `{climb rate, ground speed (m/s), seconds before it climbs}`.
  """
  @callback climb_out(performance(), pitch :: number() | nil) :: {float(), float(), float()}

  @doc "Every airframe, as `pick(airframe: ...)` names them."
  @spec all() :: [t()]
  def all, do: @all

  @doc """
  The module of `airframe`. `nil` (a mission compiled for no vehicle in
  particular, a raw mission for a vehicle of unknown airframe) is the
  report's vehicle, a copter.
  """
  @spec of(t() | nil) :: module()
  def of(nil), do: Dolphin.Airframe.Copter
  def of(:copter), do: Dolphin.Airframe.Copter
  def of(:plane), do: Dolphin.Airframe.Plane
  def of(:quadplane), do: Dolphin.Airframe.Plane
  def of(:rover), do: Dolphin.Airframe.Ground
  def of(:boat), do: Dolphin.Airframe.Ground
  def of(:sub), do: Dolphin.Airframe.Sub

  @doc "The airframes that take off and fly (what a mission with a take-off needs)."
  @spec takes_off() :: [t()]
  def takes_off, do: Enum.filter(@all, &of(&1).takes_off?())

  @doc "The airframes that have a landing (what a mission with a landing needs)."
  @spec lands() :: [t()]
  def lands, do: Enum.filter(@all, &of(&1).lands?())

  @doc "Whether `airframe` takes off and flies (`nil`: as a copter)."
  @spec takes_off?(t() | nil) :: boolean()
  def takes_off?(airframe), do: of(airframe).takes_off?()

  @doc "What an item's height means to `airframe`."
  @spec heights(t() | nil) :: heights()
  def heights(airframe), do: of(airframe).heights()

  @doc "The performance of `airframe` (see `t:performance/0`)."
  @spec performance(t() | nil) :: performance()
  def performance(airframe), do: of(airframe).performance()

  @doc """
  The current (A) `airframe` draws at `speed` and `climb` (m/s), in the air
  or on the ground: the energy model of the pre-flight check and of the
  simulator's battery.

      iex> Dolphin.Airframe.current(:copter, 0.0, 0.0, true)
      30.0
      iex> Dolphin.Airframe.current(:rover, 2.5, 0.0, true)
      6.2
  """
  @spec current(t() | nil, float(), float(), boolean()) :: float()
  def current(airframe, speed, climb, airborne?) do
    module = of(airframe)
    module.current(module.performance(), speed, climb, airborne?)
  end

  @doc "The radius (m) a loiter of `radius` is flown at by `airframe`."
  @spec flown_radius(t() | nil, number()) :: float()
  def flown_radius(airframe, radius) do
    module = of(airframe)
    module.flown_radius(module.performance(), radius)
  end

  @doc "The smallest radius (m) `airframe` turns at at `speed`."
  @spec turn_radius(t() | nil, float()) :: float()
  def turn_radius(airframe, speed) do
    module = of(airframe)
    module.turn_radius(module.performance(), speed)
  end

  @doc false
  # The figures every airframe shares unless its module says otherwise:
  # ArduCopter's, and a 3300 mAh pack.
  @spec base_performance() :: performance()
  def base_performance do
    %{
      cruise_speed: 10.0,
      climb_speed: 2.5,
      descent_speed: 1.5,
      circle_speed: 5.0,
      # Accelerations (m/s²) and CIRCLE_RATE (°/s) as ArduCopter flew the
      # differential test's missions: its jerk-limited WPNAV_ACCEL of 2.5 m/s²
      # averages about 1.5 on a leg; BRAKE decelerates hard (BRAKE_DECEL...).
      circle_rate: 20.0,
      accel: 1.5,
      brake_accel: 8.0,
      accel_z: 1.0,
      wp_radius: 2.0,
      hover_current: 30.0,
      capacity_mah: 3300.0,
      min_speed: nil,
      max_speed: nil,
      max_loiter_radius: 2550.0,
      least_take_off: 0.0,
      landed_disarm_s: 0.0,
      hold_speed: 0.0,
      landing: :vertical
    }
  end

  @doc """
  Makes the module an airframe, with what most airframes do unless it says
  otherwise: a landing is one NAV_LAND, heights are above sea level, a
  loiter is flown at its radius as given, it turns on the spot, and climbs
  out straight up at its climb speed; its fence reports or returns home.
  """
  defmacro __using__(_opts) do
    quote do
      @behaviour Dolphin.Airframe

      @impl true
      def landing_commands, do: [:mav_cmd_nav_land]
      @impl true
      def heights, do: :altitude
      @impl true
      def flown_radius(_p, radius), do: radius * 1.0
      @impl true
      def turn_radius(_p, _speed), do: 0.0
      @impl true
      def climb_out(p, _pitch), do: {p.climb_speed, 0.0, 0.0}
      # Every firmware's fence reports (0) and returns home (1).
      @impl true
      def fence_action(:report), do: 0
      def fence_action(:rtl), do: 1
      def fence_action(_other), do: nil

      defoverridable landing_commands: 0, heights: 0, flown_radius: 2, turn_radius: 2, climb_out: 2, fence_action: 1
    end
  end
end
