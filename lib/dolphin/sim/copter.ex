defmodule Dolphin.Sim.Copter do
  @moduledoc false
  # A simulated ArduCopter as a pure model: what it does with a message from a
  # ground station (`handle/3`) and with the passing of time (`step/2`). Both
  # queue what the vehicle says (`{compid, message}`), taken with `flush/1`.
  # The process around it (Dolphin.Sim.Vehicle) only moves bytes and time.
  #
  # Behaviour follows ARDUPILOT.md: modes by ArduCopter number, arming refused
  # in AUTO and until the position estimate is ready, auto-disarm on the ground,
  # MISSION_START from GUIDED switching to AUTO, MISSION_CURRENT states, the
  # final RTL item reached only after landing, pilot modes descending without
  # RC throttle, BRAKE and GUIDED holding.
  #
  # This module holds the state and composes the concerns, each a pure module
  # over the same struct: Copter.Commands (COMMAND_LONG/INT), Copter.Modes
  # (modes, arming, the land detector's disarm, the GCS failsafe),
  # Copter.Mission (flying the items in AUTO), Copter.Flight (kinematics),
  # Copter.Battery (drain, charge, battery failsafe) and Copter.Camera.
  # Dolphin.Sim.Streams builds the telemetry, Dolphin.Sim.MissionServer runs
  # the mission protocol.
  #
  # Positions are kept as metres north/east of the boot position on the
  # tangent plane there (Dolphin.Geo.tangent_plane/1, exact enough over a
  # flight's few kilometres) and metres above mean sea level; the ground is
  # flat at the boot altitude.

  alias Dolphin.Geo
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.{MissionServer, Streams}
  alias Dolphin.Sim.Copter.{Battery, Camera, Commands, Fence, Flight, Mission, Modes}

  @autopilot 1

  # How it moves and what it draws: its airframe's figures (Dolphin.Airframe),
  # the ones the pre-flight check estimates with.
  @motion [:cruise_speed, :climb_speed, :descent_speed, :accel, :brake_accel, :accel_z, :circle_rate, :circle_speed, :wp_radius, :hover_current, :capacity_mah]

  @defaults Map.merge(
              %{
                # :copter (ArduCopter), or ArduPlane's :plane, ArduRover's :rover and :boat, ArduSub's :sub
                # (see airframe_defaults/1 and docs/simulator.md).
                airframe: :copter,
                camera: false,
                rtl_alt: 15.0,
                ekf_ready_ms: 15_000,
                # How long the vehicle reports MAV_STATE BOOT (ArduCopter SITL: ~2 s);
                # 0 for none.
                boot_ms: 0,
                disarm_delay_ms: 10_000,
                # The motors spool up this long before a take-off leaves the
                # ground (about 3 s on ArduCopter SITL between "Arming motors"
                # and the first metre).
                spool_up_ms: 3_000,
                battery: 1.0,
                charge_rate: 0.005,
                charger: nil,
                arm_min_battery: 0.2,
                battery_low: 0.2,
                battery_critical: 0.1,
                battery_failsafe: :none,
                gcs_failsafe: false,
                # A fault: disarmed again at once after each of the next N arms.
                disarms_at_arming: 0,
                gcs_sysid: 255,
                request_int: false,
                # A fault: the next N uploads given up at their last item (Dolphin.Sim.MissionServer).
                gives_up_uploads: 0,
                # A fault: commands (MAV_CMD numbers) run but never acknowledged.
                unacked_commands: []
              },
              Map.take(Dolphin.Airframe.Copter.performance(), @motion)
            )

  defstruct sysid: 1,
            uid: 1,
            config: @defaults,
            origin: %{lat: 0.0, lon: 0.0, alt: 0.0},
            plane: nil,
            time_ms: 0,
            # Real (monotonic) ms when the vehicle process last gave the
            # model time or a message: an upload's patience counts it too
            # (Dolphin.Sim.MissionServer). nil: vehicle time only.
            real_ms: nil,
            n: 0.0,
            e: 0.0,
            alt: 0.0,
            vn: 0.0,
            ve: 0.0,
            vz: 0.0,
            heading: 0.0,
            mode: :stabilize,
            armed: false,
            landed: :on_ground,
            nav: :idle,
            home: nil,
            speed: 10.0,
            missions: %MissionServer{},
            current: 0,
            resume: nil,
            mission_state: 1,
            item: nil,
            jumps: %{},
            burst: 0,
            battery: 1.0,
            consumed_mah: 0.0,
            current_a: 0.0,
            battery_warned: nil,
            arm_blocked: false,
            ground_since: nil,
            photos: 0,
            # The geofence's breaches (Copter.Fence).
            fence: %{bits: 0, count: 0, time_ms: 0, recovery_until: 0, zones: nil},
            capture: nil,
            # Sent unasked: the heartbeat at 1 Hz, TIMESYNC every 10 s.
            streams: %{0 => 1000, 111 => 10_000},
            due: %{0 => 1000, 111 => 10_000},
            # The earliest time in `due`, or earlier (see Streams.due/1).
            next_due: 0,
            gcs_heard_ms: nil,
            failsafe: nil,
            prearm_text_ms: nil,
            params: %{},
            out: []

  @type t :: %__MODULE__{}

  @doc false
  def defaults, do: @defaults

  @doc false
  # What differs from a copter's settings: its airframe's figures
  # (Dolphin.Airframe.Plane, .Ground, .Sub, each as its SITL flew).
  def airframe_defaults(airframe), do: Map.take(Dolphin.Airframe.performance(airframe), @motion)

  @doc false
  # The HEARTBEAT's MAV_TYPE of each airframe.
  def mav_type(%{config: %{airframe: :plane}}), do: 1
  def mav_type(%{config: %{airframe: :rover}}), do: 10
  def mav_type(%{config: %{airframe: :boat}}), do: 11
  def mav_type(%{config: %{airframe: :sub}}), do: 12
  def mav_type(_copter), do: 2

  @doc false
  # Whether it flies (takes off, lands, hovers): a copter; rovers, boats and
  # submarines move only armed, and have no land detector.
  def flies?(%{config: %{airframe: airframe}}), do: Dolphin.Airframe.takes_off?(airframe)

  @doc "A vehicle just booted at `origin` (`%{lat, lon, alt}`), on the ground, disarmed."
  @spec new(byte(), map(), map()) :: t()
  def new(sysid, origin, config \\ %{}) do
    airframe = Map.get(config, :airframe, :copter)
    config = @defaults |> Map.merge(airframe_defaults(airframe)) |> Map.merge(config)

    %__MODULE__{
      sysid: sysid,
      uid: unique_id(),
      config: config,
      origin: origin,
      plane: Geo.tangent_plane(origin),
      alt: origin.alt,
      # ArduRover and ArduSub boot in MANUAL.
      mode: if(airframe == :copter, do: :stabilize, else: :manual),
      speed: config.cruise_speed,
      battery: config.battery,
      missions: MissionServer.new(request_int: config.request_int, gives_up: config.gives_up_uploads),
      params: Streams.default_params(sysid, config)
    }
  end

  @doc """
  A new autopilot's unique id (AUTOPILOT_VERSION `uid`), as a board's serial
  number: random, so that two simulated vehicles with one system id, in one
  ground station or in two, are told apart as real ones are. A vehicle keeps
  its own through reboots (`reboot/1`, and `Dolphin.Sim` gives a restarted
  vehicle process the one it started with).
  """
  @spec unique_id() :: pos_integer()
  def unique_id do
    <<uid::64>> = :crypto.strong_rand_bytes(8)
    max(uid, 1)
  end

  @doc "Reboots: the state of a fresh boot where the vehicle stands, its missions kept (they live in its storage)."
  @spec reboot(t()) :: t()
  def reboot(%__MODULE__{} = c) do
    {lat, lon} = latlon(c, c.n, c.e)
    fresh = new(c.sysid, %{lat: lat, lon: lon, alt: c.origin.alt}, c.config)
    %{fresh | uid: c.uid, missions: c.missions, battery: c.battery, params: c.params, out: c.out}
  end

  @doc "What the vehicle has said since the last flush, oldest first."
  @spec flush(t()) :: {[{byte(), struct()}], t()}
  def flush(%__MODULE__{out: out} = c), do: {Enum.reverse(out), %{c | out: []}}

  # ---------------------------------------------------------------------------
  # Public facts for tests and the simulator's API, and the frame the
  # concerns share.

  @doc "Where the vehicle is: `%{lat, lon, alt, relative_alt}`."
  @spec position(t()) :: %{lat: float(), lon: float(), alt: float(), relative_alt: float()}
  def position(%__MODULE__{} = c) do
    {lat, lon} = latlon(c, c.n, c.e)
    %{lat: lat, lon: lon, alt: c.alt, relative_alt: c.alt - home_alt(c)}
  end

  @doc false
  def latlon(%__MODULE__{plane: plane}, north, east), do: Geo.from_tangent(plane, north, east)

  @doc false
  def ne(%__MODULE__{plane: plane}, lat, lon), do: Geo.to_tangent(plane, lat, lon)

  @doc "The point `north`, `east` metres from `origin` (`%{lat, lon, alt}`), as the simulator places it."
  @spec offset(point, number(), number()) :: point when point: %{required(:lat) => number(), required(:lon) => number(), optional(atom()) => term()}
  defdelegate offset(origin, north, east), to: Geo, as: :tangent_offset

  @doc false
  # Metres on the plane from the vehicle to the point `n`, `e`.
  def distance_to(c, n, e), do: :math.sqrt((c.n - n) ** 2 + (c.e - e) ** 2)

  @doc false
  def ground(c), do: c.origin.alt

  @doc false
  # A submarine's surface: where it booted (its depth is 0 there).
  def surface(c), do: c.origin.alt

  @doc false
  def home_alt(%{home: nil} = c), do: ground(c)
  def home_alt(%{home: home}), do: home.alt

  @doc false
  def home_ne(%{home: nil}), do: {0.0, 0.0}
  def home_ne(%{home: home} = c), do: ne(c, home.lat, home.lon)

  @doc false
  def ready?(c), do: c.time_ms >= c.config.ekf_ready_ms

  @doc false
  # A rover, boat or submarine is "in the air" (under way) while armed.
  def in_air?(c), do: if(flies?(c), do: c.landed in [:in_air, :landing, :takeoff] and c.alt > ground(c) + 0.05, else: c.armed)

  @doc false
  # Altitude AMSL of a z given in a MAV_FRAME.
  def target_alt(c, frame, z) when frame in [3, 6], do: home_alt(c) + z
  def target_alt(c, frame, z) when frame in [10, 11], do: ground(c) + z
  def target_alt(_c, _frame, z), do: z * 1.0

  @doc false
  def resolve_alt(c, {frame, z}), do: target_alt(c, frame, z)
  def resolve_alt(_c, alt) when is_number(alt), do: alt * 1.0

  @doc false
  # A new home, announced with HOME_POSITION.
  def set_home(c, point) do
    c = put_home(c, point)
    say(c, Streams.message(c, 242))
  end

  @doc false
  # A new home, not announced yet.
  def put_home(c, %{lat: lat, lon: lon, alt: alt}), do: %{c | home: %{lat: lat, lon: lon, alt: resolve_alt(c, alt)}}

  # ---------------------------------------------------------------------------
  # Messages from a ground station.

  @doc "One message from the ground station `{sysid, compid}`."
  @spec handle(t(), struct(), {byte(), byte()}) :: t()
  def handle(c, message, from) do
    before = length(c.out)
    c |> handle_message(message, from) |> Mission.latest_reports(before)
  end

  defp handle_message(c, %M.Heartbeat{}, {sysid, _}) do
    if sysid == c.config.gcs_sysid, do: %{c | gcs_heard_ms: c.time_ms}, else: c
  end

  defp handle_message(c, %M.CommandLong{} = cmd, from) do
    params = [cmd.param1, cmd.param2, cmd.param3, cmd.param4, cmd.param5, cmd.param6, cmd.param7]
    Commands.command(c, cmd.command, params, nil, cmd.target_component, from)
  end

  defp handle_message(c, %M.CommandInt{} = cmd, from) do
    params = [cmd.param1, cmd.param2, cmd.param3, cmd.param4]
    Commands.command(c, cmd.command, params, {cmd.frame, cmd.x, cmd.y, cmd.z}, cmd.target_component, from)
  end

  defp handle_message(c, %M.SetMode{custom_mode: mode}, _from), do: elem(Modes.set_mode(c, mode), 1)

  defp handle_message(c, %M.RequestDataStream{} = r, _from), do: Streams.request_stream(c, r.req_stream_id, r.req_message_rate, r.start_stop)

  defp handle_message(c, %M.MissionSetCurrent{seq: seq}, _from), do: Mission.set_current(c, seq)

  # A guided-mode target sent as a mission item (ArduPilot's "current = 2" convention).
  defp handle_message(c, %item{current: 2} = i, {sysid, compid}) when item in [M.MissionItemInt, M.MissionItem] do
    {lat, lon} = Mission.item_latlon(i)
    ack = %M.MissionAck{target_system: sysid, target_component: compid, type: 0, mission_type: 0}

    case Flight.guided_goto(c, lat, lon, target_alt(c, i.frame, i.z)) do
      {:ok, c} -> say(c, ack)
      {:error, c} -> say(c, %{ack | type: 1})
    end
  end

  defp handle_message(c, %M.SetPositionTargetGlobalInt{} = t, _from) do
    if c.mode == :guided do
      {_, c} = Flight.guided_goto(c, t.lat_int / 1.0e7, t.lon_int / 1.0e7, target_alt(c, t.coordinate_frame, t.alt))
      c
    else
      c
    end
  end

  # A ground station's TIMESYNC request is answered with our time (tc1).
  defp handle_message(c, %M.Timesync{tc1: 0, ts1: ts1}, _from), do: say(c, %M.Timesync{tc1: c.time_ms * 1_000_000, ts1: ts1})
  defp handle_message(c, %M.Timesync{}, _from), do: c

  defp handle_message(c, %M.ParamRequestList{}, _from), do: Streams.send_params(c)
  defp handle_message(c, %M.ParamRequestRead{} = r, _from), do: Streams.send_param(c, r.param_id, r.param_index)
  defp handle_message(c, %M.ParamSet{} = p, _from), do: Streams.set_param(c, p.param_id, p.param_value)

  # While it boots (MAV_STATE BOOT), ArduCopter already answers the mission
  # protocol but its mission store is not set up: every upload is refused
  # with NO_SPACE (docs/ardupilot.md).
  defp handle_message(c, %M.MissionCount{mission_type: type}, {sysid, compid}) when c.time_ms < c.config.boot_ms,
    do: say(c, %M.MissionAck{target_system: sysid, target_component: compid, type: 4, mission_type: type})

  defp handle_message(c, message, from) do
    {missions, replies} = MissionServer.handle(c.missions, message, from, %{now: c.time_ms, real: c.real_ms, home: Mission.home_item(c)})
    mission_replies(%{c | missions: missions}, replies)
  end

  @doc "Runs the mission server's timer."
  @spec mission_timeout(t()) :: t()
  def mission_timeout(c) do
    {missions, replies} = MissionServer.timeout(c.missions, c.time_ms, c.real_ms)
    mission_replies(%{c | missions: missions}, replies)
  end

  defp mission_replies(c, replies) do
    Enum.reduce(replies, c, fn
      {:send, message}, c -> say(c, message)
      {:text, severity, text}, c -> text(c, severity, text)
      {:changed, 0}, c -> Mission.changed(c)
      {:changed, _}, c -> c
    end)
  end

  # ---------------------------------------------------------------------------
  # The passing of time.

  @doc "Advances the vehicle by `dt_ms` of its time."
  @spec step(t(), pos_integer()) :: t()
  def step(%__MODULE__{} = c, dt_ms), do: c |> advance(dt_ms) |> Streams.due()

  @doc """
  A step without its telemetry streams: what the vehicle process runs when
  it catches up with the clock after a pause of the host, sending the
  streams once, for the present, after the last (`Streams.due/1` skips
  what fell due meanwhile) — no autopilot sends a burst of old positions.
  """
  @spec advance(t(), pos_integer()) :: t()
  def advance(%__MODULE__{} = c, dt_ms) do
    was_ready = ready?(c)
    c = %{c | time_ms: c.time_ms + dt_ms, burst: 0}
    before = length(c.out)

    c = boot_events(c, was_ready)

    c
    |> Flight.fly(dt_ms / 1000)
    |> Fence.avoid(c)
    |> Flight.touchdown()
    |> Mission.check_item()
    |> Modes.auto_disarm()
    |> Camera.capture()
    |> Battery.step(dt_ms / 1000)
    |> Fence.step()
    |> Modes.gcs_failsafe()
    |> mission_timeout()
    |> Mission.latest_reports(before)
  end

  defp boot_events(c, was_ready) do
    cond do
      ready?(c) and c.home == nil ->
        c = if was_ready, do: c, else: text(c, 6, "EKF3 IMU0 is using GPS")
        set_home(c, %{lat: c.origin.lat, lon: c.origin.lon, alt: c.origin.alt})

      not ready?(c) and (c.prearm_text_ms == nil or c.time_ms - c.prearm_text_ms >= 30_000) ->
        %{text(c, 2, "PreArm: Need Position Estimate") | prearm_text_ms: c.time_ms}

      true ->
        c
    end
  end

  # ---------------------------------------------------------------------------

  @doc false
  def say(c, message, compid \\ @autopilot), do: %{c | out: [{compid, message} | c.out]}

  @doc false
  # Where the vehicle is, as a location (its height above mean sea level).
  def location(c) do
    {lat, lon} = Geo.from_tangent(c.plane, c.n, c.e)
    Geo.location(lat, lon, c.alt)
  end

  @doc false
  def text(c, severity, text), do: say(c, %M.Statustext{severity: severity, text: binary_part(text, 0, min(byte_size(text), 50))})
end
