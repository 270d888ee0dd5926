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
  # Positions are kept as metres north/east of the boot position (on an
  # ellipsoidal tangent plane, exact enough over a flight's few kilometres)
  # and metres above mean sea level; the ground is flat at the boot altitude.

  import Bitwise

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.{MissionServer, Streams}
  alias Dolphin.Vehicles.Modes

  @autopilot 1
  @camera 100
  @force_arm 21_196

  # Mode behaviour groups.
  @pilot_modes [:stabilize, :acro, :alt_hold, :loiter, :drift, :sport, :flip, :autotune, :poshold, :throw,
                :guided_nogps, :flowhold, :zigzag, :systemid, :autorotate, :turtle, :circle, :follow, :avoid_adsb,
                :smart_rtl, :auto_rtl]
  # GUIDED is entered before the position estimate is ready (ARDUPILOT.md:
  # arming in GUIDED is what is refused until then).
  @not_armable [:auto, :rtl, :land, :brake, :circle, :smart_rtl, :auto_rtl, :follow, :avoid_adsb, :throw, :autorotate]
  @needs_position [:auto, :loiter, :rtl, :circle, :poshold, :brake, :follow, :smart_rtl, :zigzag, :auto_rtl]

  # Mission item names as ArduPilot announces them ("Mission: 2 WP").
  @item_names %{
    16 => "WP", 17 => "LoitUnlim", 18 => "LoitTurns", 19 => "LoitTime", 20 => "RTL", 21 => "Land",
    22 => "Takeoff", 93 => "Delay", 112 => "CondDelay", 113 => "CondChangeAlt", 114 => "CondDist",
    115 => "CondYaw", 177 => "Jump", 178 => "ChangeSpeed", 179 => "SetHome", 186 => "ChangeAlt",
    203 => "DigiCamCtrl", 206 => "SetCamTrigDst", 2000 => "ImageStartCapture", 2001 => "ImageStopCapture"
  }

  @spool_up_ms 3_000

  @defaults %{
    camera: false,
    cruise_speed: 10.0,
    climb_speed: 2.5,
    descent_speed: 1.5,
    # Accelerations (m/s²) and CIRCLE_RATE (°/s) as ArduCopter flew the
    # differential test's missions: its jerk-limited WPNAV_ACCEL of 2.5 m/s²
    # averages about 1.5 on a leg; BRAKE decelerates hard (BRAKE_DECEL...).
    accel: 1.5,
    brake_accel: 8.0,
    accel_z: 1.0,
    circle_rate: 20.0,
    wp_radius: 2.0,
    rtl_alt: 15.0,
    circle_speed: 5.0,
    ekf_ready_ms: 15_000,
    # How long the vehicle reports MAV_STATE BOOT (ArduCopter SITL: ~2 s);
    # 0 for none.
    boot_ms: 0,
    disarm_delay_ms: 10_000,
    capacity_mah: 3300.0,
    hover_current: 30.0,
    battery: 1.0,
    charge_rate: 0.005,
    charger: nil,
    arm_min_battery: 0.2,
    battery_low: 0.2,
    battery_critical: 0.1,
    battery_failsafe: :none,
    gcs_failsafe: false,
    gcs_sysid: 255,
    request_int: false
  }

  defstruct sysid: 1,
            config: @defaults,
            origin: %{lat: 0.0, lon: 0.0, alt: 0.0},
            radii: {1.0, 1.0},
            time_ms: 0,
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
            capture: nil,
            # Sent unasked: the heartbeat at 1 Hz, TIMESYNC every 10 s.
            streams: %{0 => 1000, 111 => 10_000},
            due: %{0 => 1000, 111 => 10_000},
            gcs_heard_ms: nil,
            failsafe: nil,
            prearm_text_ms: nil,
            params: %{},
            out: []

  @type t :: %__MODULE__{}

  @doc false
  def defaults, do: @defaults

  @doc "A vehicle just booted at `origin` (`%{lat, lon, alt}`), on the ground, disarmed."
  @spec new(byte(), map(), map()) :: t()
  def new(sysid, origin, config \\ %{}) do
    config = Map.merge(@defaults, config)

    %__MODULE__{
      sysid: sysid,
      config: config,
      origin: origin,
      radii: radii(origin.lat),
      alt: origin.alt,
      speed: config.cruise_speed,
      battery: config.battery,
      missions: MissionServer.new(request_int: config.request_int),
      params: Streams.default_params(sysid, config)
    }
  end

  @doc "Reboots: the state of a fresh boot where the vehicle stands, its missions kept (they live in its storage)."
  @spec reboot(t()) :: t()
  def reboot(%__MODULE__{} = c) do
    {lat, lon} = latlon(c, c.n, c.e)
    fresh = new(c.sysid, %{lat: lat, lon: lon, alt: c.origin.alt}, c.config)
    %{fresh | missions: c.missions, battery: c.battery, params: c.params, out: c.out}
  end

  @doc "What the vehicle has said since the last flush, oldest first."
  @spec flush(t()) :: {[{byte(), struct()}], t()}
  def flush(%__MODULE__{out: out} = c), do: {Enum.reverse(out), %{c | out: []}}

  # ---------------------------------------------------------------------------
  # Public facts for tests and the simulator's API.

  @doc "Where the vehicle is: `%{lat, lon, alt, relative_alt}`."
  def position(%__MODULE__{} = c) do
    {lat, lon} = latlon(c, c.n, c.e)
    %{lat: lat, lon: lon, alt: c.alt, relative_alt: c.alt - home_alt(c)}
  end

  @doc false
  def latlon(%__MODULE__{origin: o, radii: {m, n}}, north, east) do
    {o.lat + rad2deg(north / m), o.lon + rad2deg(east / (n * :math.cos(deg2rad(o.lat))))}
  end

  @doc "The point `north`, `east` metres from `origin` (`%{lat, lon, alt}`)."
  def offset(origin, north, east) do
    {lat, lon} = latlon(%__MODULE__{origin: origin, radii: radii(origin.lat)}, north, east)
    %{origin | lat: lat, lon: lon}
  end

  @doc false
  def ne(%__MODULE__{origin: o, radii: {m, n}}, lat, lon) do
    {deg2rad(lat - o.lat) * m, deg2rad(lon - o.lon) * n * :math.cos(deg2rad(o.lat))}
  end

  # WGS84 radii of curvature (meridian, prime vertical) at a latitude.
  defp radii(lat) do
    a = 6_378_137.0
    f = 1 / 298.257223563
    e2 = f * (2 - f)
    s = :math.sin(deg2rad(lat))
    w = 1 - e2 * s * s
    {a * (1 - e2) / :math.pow(w, 1.5), a / :math.sqrt(w)}
  end

  defp deg2rad(d), do: d * :math.pi() / 180
  defp rad2deg(r), do: r * 180 / :math.pi()

  defp ground(c), do: c.origin.alt
  defp home_alt(%{home: nil} = c), do: ground(c)
  defp home_alt(%{home: home}), do: home.alt
  defp ready?(c), do: c.time_ms >= c.config.ekf_ready_ms
  defp in_air?(c), do: c.landed in [:in_air, :landing, :takeoff] and c.alt > ground(c) + 0.05

  # ---------------------------------------------------------------------------
  # Messages from a ground station.

  @doc "One message from the ground station `{sysid, compid}`."
  @spec handle(t(), struct(), {byte(), byte()}) :: t()
  def handle(c, message, from) do
    before = length(c.out)
    c |> handle_message(message, from) |> latest_mission_reports(before)
  end

  defp handle_message(c, %M.Heartbeat{}, {sysid, _}) do
    if sysid == c.config.gcs_sysid, do: %{c | gcs_heard_ms: c.time_ms}, else: c
  end

  defp handle_message(c, %M.CommandLong{} = cmd, from) do
    params = [cmd.param1, cmd.param2, cmd.param3, cmd.param4, cmd.param5, cmd.param6, cmd.param7]
    command(c, cmd.command, params, nil, cmd.target_component, from)
  end

  defp handle_message(c, %M.CommandInt{} = cmd, from) do
    params = [cmd.param1, cmd.param2, cmd.param3, cmd.param4]
    command(c, cmd.command, params, {cmd.frame, cmd.x, cmd.y, cmd.z}, cmd.target_component, from)
  end

  defp handle_message(c, %M.SetMode{custom_mode: mode}, _from), do: elem(set_mode(c, mode), 1)

  defp handle_message(c, %M.RequestDataStream{} = r, _from), do: Streams.request_stream(c, r.req_stream_id, r.req_message_rate, r.start_stop)

  defp handle_message(c, %M.MissionSetCurrent{seq: seq}, _from), do: set_current(c, seq)

  # A guided-mode target sent as a mission item (ArduPilot's "current = 2" convention).
  defp handle_message(c, %item{current: 2} = i, {sysid, compid}) when item in [M.MissionItemInt, M.MissionItem] do
    {lat, lon} = item_latlon(i)
    ack = %M.MissionAck{target_system: sysid, target_component: compid, type: 0, mission_type: 0}

    case guided_goto(c, lat, lon, target_alt(c, i.frame, i.z)) do
      {:ok, c} -> say(c, ack)
      {:error, c} -> say(c, %{ack | type: 1})
    end
  end

  defp handle_message(c, %M.SetPositionTargetGlobalInt{} = t, _from) do
    if c.mode == :guided do
      {_, c} = guided_goto(c, t.lat_int / 1.0e7, t.lon_int / 1.0e7, target_alt(c, t.coordinate_frame, t.alt))
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
    {missions, replies} = MissionServer.handle(c.missions, message, from, %{now: c.time_ms, home: home_item(c)})
    mission_replies(%{c | missions: missions}, replies)
  end

  @doc "Runs the mission server's timer."
  @spec mission_timeout(t()) :: t()
  def mission_timeout(c) do
    {missions, replies} = MissionServer.timeout(c.missions, c.time_ms)
    mission_replies(%{c | missions: missions}, replies)
  end

  defp mission_replies(c, replies) do
    Enum.reduce(replies, c, fn
      {:send, message}, c -> say(c, message)
      {:text, severity, text}, c -> text(c, severity, text)
      {:changed, 0}, c -> mission_changed(c)
      {:changed, _}, c -> c
    end)
  end

  # A new mission: the old progress means nothing any more. ArduCopter does
  # not report it at once: MISSION_CURRENT tells at its next period.
  defp mission_changed(c) do
    n = length(MissionServer.items(c.missions))

    cond do
      c.mode == :auto and n > 0 and c.mission_state == 3 -> %{c | current: min(max(c.current, 1), n)}
      true -> %{c | current: 0, resume: nil, jumps: %{}, mission_state: if(n == 0, do: 1, else: 2)}
    end
  end

  defp home_item(%{home: nil}), do: nil

  defp home_item(%{home: home}) do
    %M.MissionItemInt{command: 16, frame: 0, x: round(home.lat * 1.0e7), y: round(home.lon * 1.0e7), z: home.alt * 1.0, autocontinue: 1}
  end

  # ---------------------------------------------------------------------------
  # Commands (COMMAND_LONG / COMMAND_INT), each answered with a COMMAND_ACK.

  defp command(c, command, params, position, target_component, from) do
    if target_component == @camera and c.config.camera do
      {result, c} = camera_command(c, command, params)
      say(c, ack(from, command, result), @camera)
    else
      {result, c} = run_command(c, command, params, position)
      say(c, ack(from, command, result))
    end
  end

  defp ack({sysid, compid}, command, result),
    do: %M.CommandAck{command: command, result: result, target_system: sysid, target_component: compid}

  @accepted 0
  @denied 2
  @unsupported 3
  @failed 4

  # MAV_CMD_COMPONENT_ARM_DISARM
  defp run_command(c, 400, [p1, p2 | _], _), do: if(round(p1) == 1, do: arm(c, p2 == @force_arm), else: disarm(c, p2 == @force_arm))

  # MAV_CMD_DO_SET_MODE: p1 has MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, p2 is the custom mode.
  defp run_command(c, 176, [_p1, p2 | _], _), do: set_mode(c, round(p2))

  # MAV_CMD_NAV_TAKEOFF: p7 metres above home, in GUIDED, armed, on the ground.
  defp run_command(c, 22, params, position) do
    alt = takeoff_alt(c, params, position)

    cond do
      c.mode != :guided or not c.armed -> {@failed, c}
      in_air?(c) -> {@failed, c}
      true -> {@accepted, start_takeoff(c, alt)}
    end
  end

  defp run_command(c, 21, _params, _), do: set_mode_named(c, :land)
  defp run_command(c, 20, _params, _), do: set_mode_named(c, :rtl)

  # MAV_CMD_MISSION_START: to AUTO (ArduPilot switches itself), from p1 when given.
  defp run_command(c, 300, [p1 | _], _) do
    n = length(MissionServer.items(c.missions))

    cond do
      n == 0 ->
        {@failed, text(c, 4, "Mission: no mission")}

      c.armed and not in_air?(c) and not starts_with_takeoff?(c) ->
        {@failed, text(c, 2, "Auto: Missing Takeoff Cmd")}

      c.mode == :auto and c.mission_state == 3 ->
        {@accepted, c}

      c.mode == :auto ->
        first = round(p1)
        {@accepted, start_item(c, if(first >= 1 and first <= n, do: first, else: c.resume || 1))}

      true ->
        first = round(p1)
        c = if first >= 1 and first <= n, do: %{c | resume: first}, else: c
        set_mode_named(c, :auto)
    end
  end

  # MAV_CMD_DO_SET_MISSION_CURRENT
  defp run_command(c, 224, [p1 | _], _) do
    seq = round(p1)
    if seq >= 0 and seq <= length(MissionServer.items(c.missions)), do: {@accepted, set_current(c, seq)}, else: {@denied, c}
  end

  # MAV_CMD_DO_SET_HOME: p1 = 1 here, else the given point.
  defp run_command(c, 179, [p1 | _] = params, position) do
    cond do
      not ready?(c) -> {@failed, c}
      round(p1) == 1 -> {@accepted, set_home(c, position(c))}
      true -> {@accepted, set_home(c, command_point(params, position))}
    end
  end

  # MAV_CMD_DO_CHANGE_SPEED: p2 metres per second (-1: no change).
  defp run_command(c, 178, [_p1, p2 | _], _) when p2 > 0, do: {@accepted, %{c | speed: p2 * 1.0}}
  defp run_command(c, 178, _params, _), do: {@accepted, c}

  # MAV_CMD_DO_REPOSITION: fly to a point in GUIDED (bit 0 of p2: switch to GUIDED first).
  defp run_command(c, 192, [p1, p2 | _] = params, position) do
    {c, ok?} =
      if c.mode != :guided and (round(p2) &&& 1) == 1 do
        {result, c} = set_mode_named(c, :guided)
        {c, result == @accepted}
      else
        {c, c.mode == :guided}
      end

    point = command_point(params, position)

    with true <- ok?, {:ok, c} <- guided_goto(c, point.lat, point.lon, point.alt) do
      c = if p1 > 0, do: %{c | speed: p1 * 1.0}, else: c
      {@accepted, c}
    else
      _ -> {@failed, c}
    end
  end

  # MAV_CMD_SET_MESSAGE_INTERVAL (p1 message id, p2 µs; -1 off, 0 default).
  defp run_command(c, 511, [p1, p2 | _], _) do
    case Streams.set_interval(c, round(p1), p2) do
      {:ok, c} -> {@accepted, c}
      :error -> {@denied, c}
    end
  end

  # MAV_CMD_REQUEST_MESSAGE, MAV_CMD_GET_HOME_POSITION, MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES
  defp run_command(c, 512, [p1 | _], _), do: request_message(c, round(p1))
  defp run_command(c, 410, _params, _), do: request_message(c, 242)
  defp run_command(c, 520, _params, _), do: request_message(c, 148)

  # MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN (p1 = 1: reboot), refused while armed.
  defp run_command(c, 246, [p1 | _], _) do
    cond do
      c.armed -> {@failed, c}
      round(p1) == 1 -> {@accepted, %{c | out: [{:reboot, nil} | c.out]}}
      true -> {@unsupported, c}
    end
  end

  # Camera commands to the autopilot (ArduPilot's camera library).
  defp run_command(c, command, params, _) when command in [203, 206, 2000, 2001], do: camera_command(c, command, params)

  defp run_command(c, _command, _params, _), do: {@unsupported, c}

  defp request_message(c, msgid) do
    case Streams.message(c, msgid) do
      nil -> {@denied, c}
      message -> {@accepted, say(c, message)}
    end
  end

  # A COMMAND_INT carries its point in x/y/z (degE7, metres in its frame);
  # a COMMAND_LONG in p5..p7 (degrees, metres AMSL).
  defp command_point(_params, {frame, x, y, z}), do: %{lat: x / 1.0e7, lon: y / 1.0e7, alt: {frame, z}}

  defp command_point([_, _, _, _, lat, lon, alt], nil), do: %{lat: lat, lon: lon, alt: {0, alt}}

  defp takeoff_alt(c, _params, {frame, _x, _y, z}), do: target_alt(c, frame, z)
  defp takeoff_alt(c, params, nil), do: home_alt(c) + List.last(params)

  # ---------------------------------------------------------------------------
  # Arming.

  defp arm(%{armed: true} = c, _force), do: {@accepted, c}

  defp arm(c, force?) do
    reason =
      cond do
        force? -> nil
        c.mode in @not_armable -> "Arm: #{c.mode |> Atom.to_string() |> String.upcase()} mode not armable"
        not ready?(c) -> "Arm: Need Position Estimate"
        c.home == nil -> "Arm: Need Position Estimate"
        c.battery < c.config.arm_min_battery or c.arm_blocked -> "Arm: Battery 1 below minimum arming capacity"
        true -> nil
      end

    if reason do
      {@failed, text(c, 2, reason)}
    else
      # ArduCopter writes home into the mission's item 0 as it arms.
      c = %{c | armed: true, ground_since: c.time_ms, failsafe: nil, jumps: %{}, missions: MissionServer.home_written(c.missions)}
      {@accepted, text(c, 6, "Arming motors")}
    end
  end

  defp disarm(%{armed: false} = c, _force), do: {@accepted, c}

  defp disarm(c, force?) do
    if in_air?(c) and not force? do
      {@failed, text(c, 2, "Disarm: vehicle is flying")}
    else
      {@accepted, disarm_now(c)}
    end
  end

  defp disarm_now(c) do
    c = %{c | armed: false, ground_since: nil, nav: :idle, capture: nil}
    c = if in_air?(c), do: c, else: %{c | landed: :on_ground, vz: 0.0}
    c = text(c, 6, "Disarming motors")
    # A landed copter's mission starts again from item 1.
    finish_landing_item(%{c | resume: nil})
  end

  # ---------------------------------------------------------------------------
  # Modes.

  defp set_mode(c, number) do
    case Modes.name(:ardupilot, 2, number) do
      {:custom, _} -> {@failed, c}
      name -> set_mode_named(c, name)
    end
  end

  defp set_mode_named(%{mode: mode} = c, mode), do: {@accepted, c}

  defp set_mode_named(c, mode) do
    cond do
      mode in @needs_position and not ready?(c) ->
        {@failed, text(c, 2, "Mode change to #{upcase(mode)} failed: requires position")}

      mode == :auto and MissionServer.items(c.missions) == [] ->
        {@failed, text(c, 2, "Mode change to AUTO failed: no mission")}

      mode == :auto and c.armed and not in_air?(c) and not starts_with_takeoff?(c) ->
        {@failed, text(c, 2, "Auto: Missing Takeoff Cmd")}

      true ->
        {@accepted, enter_mode(leave_mode(c), mode)}
    end
  end

  defp upcase(mode), do: mode |> Atom.to_string() |> String.upcase()

  defp leave_mode(%{mode: :auto} = c) do
    # Leaving AUTO keeps the interrupted item to resume from.
    c = %{c | resume: if(c.mission_state == 3 and c.current > 0, do: c.current, else: c.resume), item: nil}
    c = if c.mission_state == 3, do: %{c | mission_state: 2}, else: c
    mission_current(c)
  end

  defp leave_mode(c), do: c

  defp enter_mode(c, :auto) do
    c = %{c | mode: :auto}
    first = c.resume || 1
    start_item(%{c | resume: nil}, first)
  end

  defp enter_mode(c, :guided), do: %{c | mode: :guided, nav: if(in_air?(c), do: {:brake}, else: :idle)}
  defp enter_mode(c, :brake), do: %{c | mode: :brake, nav: if(in_air?(c), do: {:brake}, else: :idle)}

  defp enter_mode(c, :rtl) do
    c = %{c | mode: :rtl}
    if in_air?(c), do: %{c | nav: {:rtl, :climb}}, else: ground_landing_mode(c)
  end

  defp enter_mode(c, :land) do
    c = %{c | mode: :land}
    if in_air?(c), do: %{c | nav: {:land, c.n, c.e}, landed: :landing}, else: ground_landing_mode(c)
  end

  defp enter_mode(c, mode) when mode in @pilot_modes do
    # No RC throttle: a pilot-controlled mode sinks (ARDUPILOT.md: never a hold).
    c = %{c | mode: mode}
    if in_air?(c), do: %{c | nav: {:descend}}, else: %{c | nav: :idle}
  end

  defp enter_mode(c, mode), do: %{c | mode: mode, nav: if(in_air?(c), do: {:descend}, else: :idle)}

  # RTL or LAND on the ground: the land detector disarms at once.
  defp ground_landing_mode(%{armed: true} = c), do: disarm_now(%{c | nav: :idle})
  defp ground_landing_mode(c), do: %{c | nav: :idle}

  # ---------------------------------------------------------------------------
  # GUIDED.

  # The motors spool up before the copter leaves the ground (about 3 s on
  # ArduCopter SITL between "Arming motors" and the first metre).
  defp start_takeoff(c, alt) do
    %{c | nav: {:spool_up, c.time_ms + @spool_up_ms, {:climb, c.n, c.e, alt}}, landed: :takeoff, ground_since: nil}
  end

  defp guided_goto(c, lat, lon, alt) do
    alt = resolve_alt(c, alt)

    if c.mode == :guided and in_air?(c) do
      {n, e} = ne(c, lat, lon)
      {:ok, %{c | nav: {:goto, n, e, alt}}}
    else
      {:error, c}
    end
  end

  defp resolve_alt(c, {frame, z}), do: target_alt(c, frame, z)
  defp resolve_alt(_c, alt) when is_number(alt), do: alt * 1.0

  # Altitude AMSL of a z given in a MAV_FRAME.
  defp target_alt(c, frame, z) when frame in [3, 6], do: home_alt(c) + z
  defp target_alt(c, frame, z) when frame in [10, 11], do: ground(c) + z
  defp target_alt(_c, _frame, z), do: z * 1.0

  # ---------------------------------------------------------------------------
  # Home.

  defp set_home(c, %{lat: lat, lon: lon, alt: alt}) do
    c = %{c | home: %{lat: lat, lon: lon, alt: resolve_alt(c, alt)}}
    say(c, Streams.message(c, 242))
  end

  # ---------------------------------------------------------------------------
  # Missions (AUTO).

  # As ArduPilot's starts_with_takeoff_cmd: DO commands and NAV_DELAY before
  # the first navigation command do not count.
  defp starts_with_takeoff?(c) do
    case Enum.find(MissionServer.items(c.missions), &(&1.command < 93)) do
      %{command: 22} -> true
      _ -> false
    end
  end

  defp set_current(c, seq) do
    n = length(MissionServer.items(c.missions))
    seq = if seq < 1, do: 1, else: min(seq, max(n, 1))

    cond do
      n == 0 -> c
      c.mode == :auto and c.mission_state == 3 -> start_item(c, seq)
      true -> mission_current(%{c | current: seq, resume: seq})
    end
  end

  defp mission_current(c), do: say(c, Streams.message(c, 42))

  # Items that complete at once (DO commands, jumps) are run in a row; a loop
  # of nothing else is cut, as ArduPilot bounds its search for the next command.
  @max_items_at_once 64

  defp start_item(%{burst: burst} = c, _seq) when burst >= @max_items_at_once do
    c = text(%{c | burst: 0}, 3, "Mission: too many commands without navigation")
    complete_mission(c)
  end

  defp start_item(c, seq) do
    items = MissionServer.items(c.missions)
    c = %{c | burst: c.burst + 1}

    case Enum.at(items, seq - 1) do
      nil when seq > 1 -> complete_mission(c)
      _ when seq < 1 -> c
      nil -> c
      item -> c |> Map.merge(%{current: seq, mission_state: 3}) |> begin_item(item)
    end
  end

  defp complete_mission(c) do
    c = %{c | current: 0, mission_state: 5, item: nil, resume: nil}
    # In the air with nothing more to do, ArduCopter holds where it is.
    c = if in_air?(c), do: %{c | nav: {:brake}}, else: c
    mission_current(c)
  end

  defp begin_item(c, item) do
    # NaN (MAVLink's "unset", e.g. a waypoint's yaw) and other non-numbers count as 0 here.
    item = Enum.reduce([:param1, :param2, :param3, :param4], item, fn k, i -> if is_number(Map.fetch!(i, k)), do: i, else: Map.put(i, k, 0.0) end)
    c = text(c, 6, "Mission: #{c.current} #{Map.get(@item_names, item.command, "Cmd#{item.command}")}")
    c = mission_current(c)
    c = %{c | item: %{seq: c.current, command: item.command, started_ms: c.time_ms, arrived_ms: nil, item: item}}
    run_item(c, item)
  end

  defp item_latlon(%M.MissionItemInt{x: x, y: y}), do: {x / 1.0e7, y / 1.0e7}
  defp item_latlon(%M.MissionItem{x: x, y: y}), do: {x * 1.0, y * 1.0}

  # The item's point; 0,0 means "here", as in ArduPilot.
  defp item_target(c, item) do
    {n, e} =
      case item_latlon(item) do
        {lat, lon} when lat == 0 and lon == 0 -> {c.n, c.e}
        {lat, lon} -> ne(c, lat, lon)
      end

    alt = if item.z == 0 and item.frame in [3, 6, 10, 11], do: c.alt, else: target_alt(c, item.frame, item.z)
    {n, e, alt}
  end

  defp run_item(c, %{command: 22} = item) do
    {_, _, alt} = item_target(c, %{item | x: 0, y: 0})

    cond do
      in_air?(c) and c.alt >= alt - 0.5 -> item_reached(c)
      in_air?(c) -> %{c | nav: {:climb, c.n, c.e, alt}}
      c.armed -> start_takeoff(c, alt)
      # Disarmed on the ground in AUTO: nothing flies until armed, which AUTO refuses.
      true -> c
    end
  end

  # LOITER_TURNS: ArduCopter flies to the edge of the circle, the point of it
  # nearest to where it is, then circles from there.
  defp run_item(c, %{command: 18, param3: radius} = item) do
    {n, e, alt} = item_target(c, item)
    d = :math.sqrt((c.n - n) ** 2 + (c.e - e) ** 2)
    r = abs(radius)
    {en, ee} = if d > r and d > 0.01, do: {n + (c.n - n) / d * r, e + (c.e - e) / d * r}, else: {c.n, c.e}
    %{c | nav: {:goto, en, ee, alt}}
  end

  defp run_item(c, %{command: command} = item) when command in [16, 17, 19] do
    {n, e, alt} = item_target(c, item)
    %{c | nav: {:goto, n, e, alt}}
  end

  defp run_item(c, %{command: 20}), do: if(in_air?(c), do: %{c | nav: {:rtl, :climb}}, else: item_reached(c))

  defp run_item(c, %{command: 21} = item) do
    {n, e, _} = item_target(c, %{item | z: 0.0, frame: 3})
    if in_air?(c), do: %{c | nav: {:land_at, n, e}}, else: item_reached(c)
  end

  defp run_item(c, %{command: command}) when command in [93, 112], do: %{c | nav: hold_nav(c)}

  defp run_item(c, %{command: 113, param2: alt, frame: frame}), do: %{c | nav: {:goto, c.n, c.e, target_alt(c, frame, alt)}}
  defp run_item(c, %{command: 186, param1: alt, param2: frame}), do: %{c | nav: {:goto, c.n, c.e, target_alt(c, round(frame), alt)}}

  defp run_item(c, %{command: 177, param1: target, param2: repeat} = item) do
    used = Map.get(c.jumps, item.seq, 0)
    target = round(target)

    if repeat < 0 or used < repeat do
      c = %{c | jumps: Map.put(c.jumps, item.seq, used + 1)}
      start_item(c, target)
    else
      start_item(c, c.current + 1)
    end
  end

  defp run_item(c, %{command: 178, param2: speed}) do
    c = if speed > 0, do: %{c | speed: speed * 1.0}, else: c
    item_reached(c)
  end

  defp run_item(c, %{command: 179, param1: p1} = item) do
    point =
      if round(p1) == 1 do
        position(c)
      else
        {lat, lon} = item_latlon(item)
        %{lat: lat, lon: lon, alt: {item.frame, item.z}}
      end

    item_reached(set_home(c, point))
  end

  defp run_item(c, %{command: command} = item) when command in [203, 206, 2000, 2001] do
    params = [item.param1, item.param2, item.param3, item.param4, item.x, item.y, item.z]
    {_, c} = camera_command(c, command, params)
    item_reached(c)
  end

  # Commands flown as no-ops (yaw, relays, servos, ROI...): done at once.
  defp run_item(c, _item), do: item_reached(c)

  defp hold_nav(c), do: if(in_air?(c), do: {:hold, c.n, c.e, c.alt}, else: :idle)

  defp item_reached(%{item: %{seq: seq, command: command}} = c) do
    c = say(c, %M.MissionItemReached{seq: seq})
    # ArduCopter says so only for waypoints and timed loiters.
    c = if command in [16, 19], do: text(c, 6, "Reached command ##{seq}"), else: c
    start_item(%{c | item: nil}, seq + 1)
  end

  # The item in progress, checked after each step of flight.
  defp check_item(%{mode: :auto, item: %{} = item} = c), do: check_item(c, item.command, item)
  defp check_item(c), do: c

  defp check_item(c, 22, %{item: i}) do
    {_, _, alt} = item_target(c, %{i | x: 0, y: 0})
    if in_air?(c) and c.alt >= alt - 0.5, do: item_reached(c), else: c
  end

  defp check_item(c, 16, %{item: i} = item) do
    radius = if i.param2 > 0, do: i.param2, else: c.config.wp_radius

    case c.nav do
      _ when item.arrived_ms != nil ->
        if c.time_ms - item.arrived_ms >= i.param1 * 1000, do: item_reached(c), else: c

      {:goto, n, e, alt} ->
        if dist3(c, n, e, alt) <= radius, do: %{c | item: %{item | arrived_ms: c.time_ms}}, else: c

      _ ->
        c
    end
  end

  # A copter circles only for LOITER_TURNS; LOITER_UNLIM and LOITER_TIME hold
  # at the point, whatever radius they were given (ArduCopter ignores it).
  defp check_item(c, command, %{item: i} = item) when command in [17, 18, 19] do
    case c.nav do
      {:goto, n, e, alt} ->
        cond do
          dist3(c, n, e, alt) > max(c.config.wp_radius, 1.0) -> c
          command == 18 -> circle_from_edge(c, item, alt)
          true -> %{c | nav: {:hold, n, e, alt}, item: %{item | arrived_ms: c.time_ms}}
        end

      {:hold, _, _, _} ->
        if command == 19 and c.time_ms - item.arrived_ms >= i.param1 * 1000, do: item_reached(c), else: c

      {:circle, _, _, _, radius, turned, _} ->
        cond do
          command == 18 and abs(radius) >= 1 and turned >= i.param1 * 2 * :math.pi() -> item_reached(c)
          command == 18 and abs(radius) < 1 and c.time_ms - item.arrived_ms >= i.param1 * 18_000 -> item_reached(c)
          command == 19 and c.time_ms - item.arrived_ms >= i.param1 * 1000 -> item_reached(c)
          true -> c
        end

      _ ->
        c
    end
  end

  defp check_item(c, command, %{item: i} = item) when command in [93, 112] do
    if c.time_ms - item.started_ms >= i.param1 * 1000, do: item_reached(c), else: c
  end

  defp check_item(c, command, _item) when command in [113, 186] do
    case c.nav do
      {:goto, _, _, alt} -> if abs(c.alt - alt) < 0.5, do: item_reached(c), else: c
      _ -> c
    end
  end

  # RTL and LAND items are reached when the vehicle has landed and disarmed.
  defp check_item(c, _command, _item), do: c

  defp circle_from_edge(c, %{item: i} = item, alt) do
    {n, e, _} = item_target(c, i)
    %{c | nav: {:circle, n, e, alt, i.param3, 0.0, nil}, item: %{item | arrived_ms: c.time_ms}}
  end

  # ArduCopter reports a final RETURN_TO_LAUNCH reached after the disarm, and
  # the mission complete; a final NAV_LAND never: the land item stays current
  # with the mission ACTIVE, announced again (docs/ardupilot.md).
  defp finish_landing_item(%{mode: :auto, item: %{command: 20}} = c), do: item_reached(c)

  # After that disarm ArduCopter resets its mission: item 1 current again, the
  # mission still ACTIVE, "Mission: 1 Takeoff" said (nothing flies: AUTO
  # cannot be armed).
  defp finish_landing_item(%{mode: :auto, item: %{command: 21}} = c), do: start_item(%{c | item: nil}, 1)

  defp finish_landing_item(c), do: c

  defp takeoff_follows_landing?(%{mode: :auto, item: %{command: 21, seq: seq}} = c) do
    next_nav = c.missions |> MissionServer.items() |> Enum.drop(seq) |> Enum.find(&(&1.command < 100))
    match?(%{command: 22}, next_nav)
  end

  defp takeoff_follows_landing?(_c), do: false

  defp dist3(c, n, e, alt), do: :math.sqrt((c.n - n) ** 2 + (c.e - e) ** 2 + (c.alt - alt) ** 2)

  # ---------------------------------------------------------------------------
  # Cameras: photos counted and reported (CAMERA_IMAGE_CAPTURED).

  defp camera_command(c, 203, [_, _, _, _, p5 | _]) do
    if round(p5) == 1, do: {@accepted, photo(c)}, else: {@accepted, c}
  end

  defp camera_command(c, 206, [p1, _p2, p3 | _]) do
    c = if p1 > 0, do: %{c | capture: {:distance, p1 * 1.0, {c.n, c.e}}}, else: %{c | capture: nil}
    c = if round(p3) == 1 and p1 > 0, do: photo(c), else: c
    {@accepted, c}
  end

  defp camera_command(c, 2000, [_p1, interval, count | _]) do
    c =
      cond do
        interval <= 0 or round(count) == 1 -> photo(c)
        true -> %{c | capture: {:interval, interval * 1000, c.time_ms + interval * 1000, if(count <= 0, do: :infinity, else: round(count) - 1)}} |> photo()
      end

    {@accepted, c}
  end

  defp camera_command(c, 2001, _params), do: {@accepted, %{c | capture: nil}}
  defp camera_command(c, _command, _params), do: {@unsupported, c}

  defp photo(c) do
    c = %{c | photos: c.photos + 1}
    compid = if c.config.camera, do: @camera, else: @autopilot
    say(c, Streams.image_captured(c), compid)
  end

  defp capture(%{capture: {:interval, every, next, left}} = c) when c.time_ms >= next do
    c = photo(c)
    left = if left == :infinity, do: left, else: left - 1
    if left == 0, do: %{c | capture: nil}, else: %{c | capture: {:interval, every, next + every, left}}
  end

  defp capture(%{capture: {:distance, every, {n0, e0}}} = c) do
    if :math.sqrt((c.n - n0) ** 2 + (c.e - e0) ** 2) >= every,
      do: photo(%{c | capture: {:distance, every, {c.n, c.e}}}),
      else: c
  end

  defp capture(c), do: c

  # ---------------------------------------------------------------------------
  # The passing of time.

  @doc "Advances the vehicle by `dt_ms` of its time."
  @spec step(t(), pos_integer()) :: t()
  def step(%__MODULE__{} = c, dt_ms) do
    was_ready = ready?(c)
    c = %{c | time_ms: c.time_ms + dt_ms, burst: 0}
    before = length(c.out)

    c
    |> boot_events(was_ready)
    |> fly(dt_ms / 1000)
    |> touchdown()
    |> check_item()
    |> auto_disarm()
    |> capture()
    |> battery(dt_ms / 1000)
    |> gcs_failsafe()
    |> mission_timeout()
    |> latest_mission_reports(before)
    |> Streams.due()
  end

  # ArduCopter sends MISSION_CURRENT and MISSION_ITEM_REACHED as deferred
  # messages holding only the latest value: items that end in one loop (a
  # take-off and the DO commands flown along with it) are reported once, by
  # the last of them (docs/ardupilot.md).
  defp latest_mission_reports(%{out: out} = c, before) do
    {new, old} = Enum.split(out, length(out) - before)
    last = fn module -> Enum.find(new, &match?({_, %^module{}}, &1)) end
    keep = [last.(M.MissionItemReached), last.(M.MissionCurrent)]
    new = Enum.filter(new, fn {_, m} = msg -> not is_struct(m, M.MissionItemReached) and not is_struct(m, M.MissionCurrent) or msg in keep end)
    %{c | out: new ++ old}
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

  # Desired velocity from the navigation target, then an acceleration limit:
  # that is what makes turns round and BRAKE overshoot.
  # Disarmed in the air (a forced disarm): it falls.
  defp fly(%{armed: false} = c, dt) do
    if in_air?(c), do: %{c | vn: 0.0, ve: 0.0, vz: -8.0, alt: max(c.alt - 8.0 * dt, ground(c))}, else: %{c | vn: 0.0, ve: 0.0, vz: 0.0}
  end

  defp fly(%{nav: :idle} = c, _dt), do: %{c | vn: 0.0, ve: 0.0, vz: 0.0}

  defp fly(c, dt) do
    {c, {wn, we, wz}} = desired_velocity(c)
    a = if c.nav == {:brake}, do: c.config.brake_accel, else: c.config.accel
    {vn, ve} = accelerate({c.vn, c.ve}, {wn, we}, a * dt)
    max_dz = c.config.accel_z * dt
    vz = c.vz + max(-max_dz, min(max_dz, wz - c.vz))
    heading = if vn * vn + ve * ve > 1.0, do: :math.fmod(rad2deg(:math.atan2(ve, vn)) + 360, 360), else: c.heading
    %{c | vn: vn, ve: ve, vz: vz, n: c.n + vn * dt, e: c.e + ve * dt, alt: max(c.alt + vz * dt, ground(c)), heading: heading}
  end

  defp accelerate({vn, ve}, {wn, we}, max_dv) do
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
        if :math.sqrt((c.n - n) ** 2 + (c.e - e) ** 2) <= c.config.wp_radius,
          do: {%{c | nav: {:land, n, e}, landed: :landing}, land_velocity(c, n, e)},
          else: {c, toward(c, n, e, c.alt)}

      {:descend} ->
        {c, {0.0, 0.0, -c.config.descent_speed}}

      {:rtl, :climb} ->
        target = max(c.alt, home_alt(c) + c.config.rtl_alt)
        if c.alt >= target - 0.5, do: {%{c | nav: {:rtl, :return}}, {0.0, 0.0, 0.0}}, else: {c, {0.0, 0.0, c.config.climb_speed}}

      {:rtl, :return} ->
        {hn, he} = home_ne(c)

        if :math.sqrt((c.n - hn) ** 2 + (c.e - he) ** 2) <= c.config.wp_radius,
          do: {%{c | nav: {:land, hn, he}, landed: :landing}, {0.0, 0.0, 0.0}},
          else: {c, toward(c, hn, he, c.alt)}
    end
  end

  defp home_ne(%{home: nil}), do: {0.0, 0.0}
  defp home_ne(%{home: home} = c), do: ne(c, home.lat, home.lon)

  defp land_velocity(c, n, e) do
    {wn, we, _} = toward(c, n, e, c.alt)
    {wn, we, -c.config.descent_speed}
  end

  # Speed that lets the vehicle stop at the point: sqrt(2 a d), at most the cruise speed.
  defp toward(c, n, e, alt) do
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

  @pi :math.pi()
  defp wrap(a) when a > @pi, do: a - 2 * @pi
  defp wrap(a) when a < -@pi, do: a + 2 * @pi
  defp wrap(a), do: a

  defp touchdown(c) do
    cond do
      c.landed == :takeoff and c.alt > ground(c) + 1.0 ->
        %{c | landed: :in_air}

      c.landed in [:in_air, :landing] and c.alt <= ground(c) + 0.05 and c.vz <= 0 ->
        c = %{c | landed: :on_ground, vz: 0.0, vn: 0.0, ve: 0.0, alt: ground(c), nav: :idle}

        # The land detector disarms a copter that has landed (LAND, RTL, pilot
        # modes, a mission's landing), except on a mission's NAV_LAND followed
        # by a take-off, from which ArduCopter flies on armed.
        cond do
          not c.armed -> c
          takeoff_follows_landing?(c) -> item_reached(c)
          true -> disarm_now(c)
        end

      true ->
        c
    end
  end

  defp auto_disarm(%{armed: true, landed: :on_ground, nav: :idle, ground_since: since} = c) when since != nil do
    if c.time_ms - since >= c.config.disarm_delay_ms, do: disarm_now(c), else: c
  end

  defp auto_disarm(c), do: c

  # Drain while armed, in proportion to effort; charge while disarmed on the
  # ground at home.
  defp battery(c, dt) do
    if c.armed do
      effort =
        cond do
          not in_air?(c) -> 0.15
          true -> 1.0 + 0.1 * :math.sqrt(c.vn * c.vn + c.ve * c.ve) / 10 + 0.2 * max(c.vz, 0) / 2.5
        end

      amps = c.config.hover_current * effort
      used = amps * dt / 3.6
      remaining = max(c.battery - used / c.config.capacity_mah, 0.0)
      battery_levels(%{c | battery: remaining, consumed_mah: c.consumed_mah + used, current_a: amps})
    else
      c = %{c | current_a: 0.0}

      if at_home?(c) and c.config.charge_rate > 0 and c.battery < 1.0 do
        battery = min(c.battery + c.config.charge_rate * dt, 1.0)
        blocked = c.arm_blocked and battery < c.config.battery_low
        %{c | battery: battery, consumed_mah: max(c.consumed_mah - c.config.charge_rate * dt * c.config.capacity_mah, 0.0), arm_blocked: blocked, battery_warned: if(battery >= c.config.battery_low, do: nil, else: c.battery_warned)}
      else
        c
      end
    end
  end

  defp at_home?(%{home: nil}), do: false

  # On the ground at its home, or at the fleet's charging station (where
  # missions written for the whole fleet bring every vehicle back).
  defp at_home?(c) do
    {hn, he} = home_ne(c)
    near? = fn {n, e}, r -> :math.sqrt((c.n - n) ** 2 + (c.e - e) ** 2) <= r end
    charger = c.config.charger
    c.landed == :on_ground and (near?.({hn, he}, 10) or (charger != nil and near?.(ne(c, charger.lat, charger.lon), 15)))
  end

  defp battery_levels(c) do
    # An empty pack does not stop the simulated motors (as in SITL with the
    # failsafes off): only the failsafe, when enabled, acts.
    cond do
      c.battery <= c.config.battery_critical and c.battery_warned != :critical ->
        c = %{text(c, 2, "Battery 1 is critical #{volts(c)}V used #{round(c.consumed_mah)} mAh") | battery_warned: :critical, arm_blocked: true}
        battery_failsafe(c, :land)

      c.battery <= c.config.battery_low and c.battery_warned == nil ->
        c = %{text(c, 2, "Battery 1 is low #{volts(c)}V used #{round(c.consumed_mah)} mAh") | battery_warned: :low, arm_blocked: true}
        battery_failsafe(c, :rtl)

      true ->
        c
    end
  end

  defp volts(c), do: :erlang.float_to_binary(Streams.voltage(c) / 1000, decimals: 2)

  # BATT_FS_LOW_ACT / BATT_FS_CRT_ACT: off by default, as in ArduPilot.
  defp battery_failsafe(%{config: %{battery_failsafe: :none}} = c, _action), do: c

  defp battery_failsafe(c, action) do
    if in_air?(c) do
      c = %{text(c, 2, "Battery Failsafe") | failsafe: :battery}
      action = if c.config.battery_failsafe == :land, do: :land, else: action
      {_, c} = set_mode_named(c, action)
      c
    else
      c
    end
  end

  defp gcs_failsafe(%{config: %{gcs_failsafe: true}, gcs_heard_ms: heard, failsafe: nil} = c) when heard != nil do
    if in_air?(c) and c.time_ms - heard > 5_000 do
      c = %{text(c, 2, "GCS Failsafe") | failsafe: :gcs}
      {_, c} = set_mode_named(c, :rtl)
      c
    else
      c
    end
  end

  defp gcs_failsafe(c), do: c

  # ---------------------------------------------------------------------------

  @doc false
  def say(c, message, compid \\ @autopilot), do: %{c | out: [{compid, message} | c.out]}

  @doc false
  def text(c, severity, text), do: say(c, %M.Statustext{severity: severity, text: binary_part(text, 0, min(byte_size(text), 50))})
end
