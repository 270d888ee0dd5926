defmodule Dolphin.Sim.Streams do
  @moduledoc false
  # What a simulated vehicle reports and how often: the telemetry messages
  # built from its state, the streams a ground station turned on
  # (REQUEST_DATA_STREAM, SET_MESSAGE_INTERVAL), one-off requests, and its few
  # parameters. Like ArduCopter, a vehicle sends only HEARTBEAT and STATUSTEXT
  # until a stream is asked for (and TIMESYNC, every 10 s, as ArduPilot does).

  import Bitwise

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.{Copter, MissionServer}
  alias Dolphin.Vehicles.Modes

  # MAV_DATA_STREAM -> message ids, as ArduPilot groups them. ALL does not
  # include EXTENDED_SYS_STATE: ArduPilot sends it only when asked by interval.
  @data_streams %{
    1 => [24],
    2 => [1, 24, 42, 162],
    6 => [33],
    10 => [30],
    11 => [74],
    12 => [147]
  }
  @all_streams [1, 24, 42, 33, 30, 74, 147]

  # Messages that can be streamed or requested once.
  @known [1, 24, 30, 33, 42, 74, 111, 147, 148, 162, 242, 245]

  # Parameters a ground station may read (names as ArduPilot 4.5/4.6 and 4.7).
  @doc false
  def default_params(sysid, config) do
    %{
      "SYSID_THISMAV" => sysid,
      "MAV_SYSID" => sysid,
      "SYSID_MYGCS" => config.gcs_sysid,
      "MAV_GCS_SYSID" => config.gcs_sysid,
      "WPNAV_SPEED" => config.cruise_speed * 100,
      "WPNAV_SPEED_UP" => config.climb_speed * 100,
      "WPNAV_SPEED_DN" => config.descent_speed * 100,
      "WPNAV_RADIUS" => config.wp_radius * 100,
      "RTL_ALT" => config.rtl_alt * 100,
      "BATT_CAPACITY" => config.capacity_mah,
      "DISARM_DELAY" => config.disarm_delay_ms / 1000,
      "FS_GCS_ENABLE" => if(config.gcs_failsafe, do: 1, else: 0),
      # The geofence (Copter.Fence), as ArduCopter's defaults are with copter.parm.
      "FENCE_ENABLE" => 0,
      "FENCE_TYPE" => 7,
      "FENCE_ACTION" => 1,
      "FENCE_ALT_MAX" => 100,
      "FENCE_ALT_MIN" => -10,
      "FENCE_MARGIN" => 2,
      "FENCE_RADIUS" => 150
    }
  end

  @doc "REQUEST_DATA_STREAM: a stream on at `rate` Hz, or off."
  def request_stream(c, stream, rate, start_stop) do
    ids = if stream == 0, do: @all_streams, else: Map.get(@data_streams, stream, [])

    Enum.reduce(ids, c, fn id, c ->
      if start_stop == 0 or rate == 0, do: stop(c, id), else: start(c, id, 1000 / rate)
    end)
  end

  @doc "MAV_CMD_SET_MESSAGE_INTERVAL: µs between messages, -1 off, 0 the default rate (1 Hz)."
  def set_interval(c, msgid, interval_us) do
    cond do
      msgid not in @known -> :error
      interval_us < 0 -> {:ok, stop(c, msgid)}
      interval_us == 0 -> {:ok, start(c, msgid, 1000)}
      true -> {:ok, start(c, msgid, interval_us / 1000)}
    end
  end

  defp start(c, msgid, every_ms) do
    every = max(every_ms, 1)
    %{c | streams: Map.put(c.streams, msgid, every), due: Map.put_new(c.due, msgid, c.time_ms), next_due: min(c.next_due, c.time_ms)}
  end

  defp stop(c, msgid), do: %{c | streams: Map.delete(c.streams, msgid), due: Map.delete(c.due, msgid)}

  @doc "Sends every stream that is due, and schedules its next time."
  def due(%{streams: streams} = c) when map_size(streams) == 0, do: c

  # Most steps have nothing due: `next_due` (never later than the earliest
  # time in `due`) spares the walk over the streams, the larger part of a
  # step's work.
  def due(%{time_ms: now, next_due: next} = c) when now < next, do: c

  def due(c) do
    c = send_due(c)
    %{c | next_due: c.due |> Map.values() |> Enum.min(fn -> c.time_ms end)}
  end

  defp send_due(c) do
    Enum.reduce(c.streams, c, fn {msgid, every}, c ->
      due = Map.get(c.due, msgid, c.time_ms)

      if c.time_ms >= due do
        # Late by more than a period (a slow host): skip ahead, don't burst.
        next = if c.time_ms - due >= every, do: c.time_ms + every, else: due + every
        c = %{c | due: Map.put(c.due, msgid, next)}
        c = if msg = message(c, msgid), do: Copter.say(c, msg), else: c
        if msgid == 0 and c.config.camera, do: Copter.say(c, camera_heartbeat(), 100), else: c
      else
        c
      end
    end)
  end

  @doc "The message with id `msgid` as the vehicle would send it now, or nil."
  def message(c, msgid)

  def message(c, 0), do: heartbeat(c)

  # TIMESYNC, ArduPilot's own request (tc1 = 0; ts1 its time in ns).
  def message(c, 111), do: %M.Timesync{tc1: 0, ts1: c.time_ms * 1_000_000}

  def message(c, 1) do
    ready? = c.time_ms >= c.config.ekf_ready_ms
    # Sensors: gyro, accel, mag, baro, GPS, motor outputs, battery (+ the pre-arm bit).
    sensors = 0x1 ||| 0x2 ||| 0x4 ||| 0x8 ||| 0x20 ||| 0x8000 ||| 0x200000 ||| 0x2000000
    # The pre-arm-good bit comes on before arming is really possible (ARDUPILOT.md).
    health = if c.time_ms >= c.config.ekf_ready_ms - 10_000, do: sensors ||| 0x10000000, else: sensors
    health = if ready?, do: health, else: health &&& bnot(0x20)

    %M.SysStatus{
      onboard_control_sensors_present: sensors ||| 0x10000000,
      onboard_control_sensors_enabled: sensors ||| 0x10000000,
      onboard_control_sensors_health: health,
      load: 200,
      voltage_battery: voltage(c),
      current_battery: round(c.current_a * 100),
      battery_remaining: remaining(c)
    }
  end

  def message(c, 24) do
    p = Copter.position(c)
    ready? = c.time_ms >= c.config.ekf_ready_ms

    %M.GpsRawInt{
      time_usec: c.time_ms * 1000,
      fix_type: if(ready?, do: 3, else: 1),
      lat: round(p.lat * 1.0e7),
      lon: round(p.lon * 1.0e7),
      alt: round(p.alt * 1000),
      eph: 121,
      epv: 200,
      vel: round(ground_speed(c) * 100),
      cog: round(c.heading * 100),
      satellites_visible: 10
    }
  end

  def message(c, 30), do: %M.Attitude{time_boot_ms: boot_ms(c), yaw: yaw(c)}

  def message(c, 33) do
    fields = %{time_boot_ms: boot_ms(c), vx: round(c.vn * 100), vy: round(c.ve * 100), vz: round(-c.vz * 100), hdg: rem(round(c.heading * 100), 36_000)}
    struct(M.GlobalPositionInt, Map.merge(position_fields(c), fields))
  end

  def message(c, 42) do
    total = length(MissionServer.items(c.missions))
    state = if total == 0, do: 1, else: c.mission_state

    %M.MissionCurrent{seq: c.current, total: total, mission_state: state, mission_mode: if(c.mode == :auto, do: 1, else: 0)}
  end

  def message(c, 74) do
    %M.VfrHud{
      airspeed: ground_speed(c),
      groundspeed: ground_speed(c),
      heading: round(c.heading) |> rem(360),
      throttle: if(c.armed, do: 50, else: 0),
      alt: c.alt * 1.0,
      climb: c.vz * 1.0
    }
  end

  def message(c, 147) do
    charge_state =
      cond do
        c.battery <= c.config.battery_critical -> 3
        c.battery <= c.config.battery_low -> 2
        true -> 1
      end

    %M.BatteryStatus{
      id: 0,
      battery_function: 1,
      type: 1,
      temperature: 32_767,
      voltages: [voltage(c) | List.duplicate(65_535, 9)],
      current_battery: round(c.current_a * 100),
      current_consumed: round(c.consumed_mah),
      energy_consumed: -1,
      battery_remaining: remaining(c),
      charge_state: charge_state
    }
  end

  def message(c, 148) do
    # MISSION_FLOAT, PARAM_FLOAT, MISSION_INT, COMMAND_INT, SET_POSITION_TARGET_GLOBAL_INT, MAVLINK2, MISSION_FENCE, MISSION_RALLY
    capabilities = 1 ||| 2 ||| 4 ||| 8 ||| 256 ||| 8192 ||| 16_384 ||| 32_768

    %M.AutopilotVersion{capabilities: capabilities, flight_sw_version: 0x04060000, uid: c.uid, vendor_id: 0x1209, product_id: 0x5740}
  end

  # FENCE_STATUS only while a fence is enabled.
  def message(c, 162), do: if(Dolphin.Sim.Copter.Fence.enabled?(c), do: Dolphin.Sim.Copter.Fence.status(c))

  def message(%{home: nil}, 242), do: nil

  def message(c, 242) do
    %M.HomePosition{
      latitude: round(c.home.lat * 1.0e7),
      longitude: round(c.home.lon * 1.0e7),
      altitude: round(c.home.alt * 1000),
      q: [1.0, 0.0, 0.0, 0.0],
      time_usec: c.time_ms * 1000
    }
  end

  # ArduRover and ArduSub say nothing of a landed state (MAV_LANDED_STATE_UNDEFINED).
  def message(c, 245) do
    if Dolphin.Sim.Copter.flies?(c), do: extended_sys_state(c), else: %M.ExtendedSysState{vtol_state: 0, landed_state: 0}
  end

  def message(_c, _other), do: nil

  defp extended_sys_state(c) do
    landed =
      case c.landed do
        :on_ground -> 1
        :in_air -> 2
        :takeoff -> 3
        :landing -> 4
      end

    %M.ExtendedSysState{vtol_state: 0, landed_state: landed}
  end

  @doc "The autopilot's HEARTBEAT."
  def heartbeat(c) do
    type = Dolphin.Sim.Copter.mav_type(c)
    {:ok, custom_mode} = Modes.number(:ardupilot, type, c.mode)
    # CUSTOM_MODE_ENABLED | STABILIZE_ENABLED, GUIDED_ENABLED in the autonomous modes, SAFETY_ARMED.
    base = 1 ||| 16
    base = if c.mode in [:auto, :guided, :rtl, :land, :brake, :smart_rtl, :circle], do: base ||| 8, else: base
    base = if c.armed, do: base ||| 128, else: base

    status =
      cond do
        c.time_ms < c.config.boot_ms -> 1
        c.failsafe != nil -> 5
        c.armed -> 4
        true -> 3
      end

    %M.Heartbeat{type: type, autopilot: 3, base_mode: base, custom_mode: custom_mode, system_status: status, mavlink_version: 3}
  end

  @doc "A camera component's HEARTBEAT."
  def camera_heartbeat, do: %M.Heartbeat{type: 30, autopilot: 8, base_mode: 0, custom_mode: 0, system_status: 4, mavlink_version: 3}

  @doc "CAMERA_IMAGE_CAPTURED for the photo just taken."
  def image_captured(c) do
    fields = %{time_boot_ms: boot_ms(c), q: [1.0, 0.0, 0.0, 0.0], image_index: c.photos - 1, capture_result: 1, camera_id: 0}
    struct(M.CameraImageCaptured, Map.merge(position_fields(c), fields))
  end

  # Where the vehicle is, in MAVLink's integer fields: degE7 and millimetres.
  defp position_fields(c) do
    p = Copter.position(c)
    %{lat: round(p.lat * 1.0e7), lon: round(p.lon * 1.0e7), alt: round(p.alt * 1000), relative_alt: round(p.relative_alt * 1000)}
  end

  @doc "Pack voltage in mV: a 3S LiPo sagging with charge and load."
  def voltage(c), do: round((10.5 + 2.1 * c.battery - 0.01 * c.current_a) * 1000)

  # ArduPilot's milliseconds since boot are a uint32 that wraps after 49.7
  # days of its time (at a speed-up of 1000, 72 minutes of real time).
  defp boot_ms(c), do: rem(c.time_ms, 1 <<< 32)

  # Whole percent, rounded down as ArduPilot does: 29.9 % is reported as 29.
  defp remaining(c), do: trunc(c.battery * 100)
  defp ground_speed(c), do: :math.sqrt(c.vn * c.vn + c.ve * c.ve)
  defp yaw(c), do: if(c.heading > 180, do: c.heading - 360, else: c.heading) * :math.pi() / 180

  # --- parameters -------------------------------------------------------------

  @doc "PARAM_REQUEST_LIST: every parameter."
  def send_params(c) do
    names = c.params |> Map.keys() |> Enum.sort()
    names |> Enum.with_index() |> Enum.reduce(c, fn {name, i}, c -> Copter.say(c, param_value(c, name, i, length(names))) end)
  end

  @doc "PARAM_REQUEST_READ: one parameter, by name or (index >= 0) by index."
  def send_param(c, name, index) do
    names = c.params |> Map.keys() |> Enum.sort()
    name = if index >= 0, do: Enum.at(names, index), else: name

    case Enum.find_index(names, &(&1 == name)) do
      nil -> c
      i -> Copter.say(c, param_value(c, name, i, length(names)))
    end
  end

  @doc "PARAM_SET: a known parameter takes the value and is echoed; an unknown one is ignored, as ArduPilot does."
  def set_param(c, name, value) do
    if Map.has_key?(c.params, name) do
      c = %{c | params: Map.put(c.params, name, value)} |> apply_param(name, value)
      send_param(c, name, -1)
    else
      c
    end
  end

  defp apply_param(c, name, v) when name in ["WPNAV_SPEED"], do: %{c | speed: v / 100, config: %{c.config | cruise_speed: v / 100}}
  defp apply_param(c, "WPNAV_RADIUS", v), do: %{c | config: %{c.config | wp_radius: v / 100}}
  defp apply_param(c, "RTL_ALT", v), do: %{c | config: %{c.config | rtl_alt: v / 100}}
  defp apply_param(c, "BATT_CAPACITY", v) when v > 0, do: %{c | config: %{c.config | capacity_mah: v * 1.0}}
  defp apply_param(c, "DISARM_DELAY", v), do: %{c | config: %{c.config | disarm_delay_ms: round(v * 1000)}}
  defp apply_param(c, "FS_GCS_ENABLE", v), do: %{c | config: %{c.config | gcs_failsafe: v != 0}}
  defp apply_param(c, _name, _v), do: c

  # MAV_PARAM_TYPE_REAL32 for all: ArduPilot's ground stations read every parameter as a float.
  defp param_value(c, name, index, count),
    do: %M.ParamValue{param_id: name, param_value: Map.fetch!(c.params, name) * 1.0, param_type: 9, param_count: count, param_index: index}
end
