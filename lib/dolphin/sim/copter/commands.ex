defmodule Dolphin.Sim.Copter.Commands do
  @moduledoc false
  # The simulated copter's command protocol: each COMMAND_LONG / COMMAND_INT
  # run against the model and answered with a COMMAND_ACK, from the camera
  # component when it is addressed to it and the vehicle has one.

  import Bitwise
  import Dolphin.Sim.Copter, only: [say: 2, say: 3, text: 3, in_air?: 1, ready?: 1, home_alt: 1, target_alt: 3, put_home: 2, position: 1]

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.{Copter, MissionServer, Streams}
  alias Dolphin.Sim.Copter.{Camera, Flight, Mission, Modes}

  @camera 100
  @force_arm 21_196

  # MAV_RESULT
  @accepted 0
  @denied 2
  @unsupported 3
  @failed 4

  @doc false
  # `position` is a COMMAND_INT's `{frame, x, y, z}`, nil for a COMMAND_LONG.
  @spec command(Copter.t(), non_neg_integer(), [number()], {integer(), integer(), integer(), number()} | nil, byte(), {byte(), byte()}) :: Copter.t()
  def command(c, command, params, position, target_component, from) do
    if target_component == @camera and c.config.camera do
      {result, c} = Camera.command(c, command, params)
      say(c, ack(from, command, result), @camera)
    else
      # What a command asks to be sent goes out after its COMMAND_ACK, as
      # ArduPilot queues it for its next round of sending (but see 410 below).
      {result, c, afterwards} =
        case run_command(c, command, params, position) do
          {result, c} -> {result, c, []}
          {result, c, messages} -> {result, c, messages}
        end

      # The unacked_commands fault: as ArduPilot when its link to the ground
      # station has no room, the command is run and its COMMAND_ACK dropped.
      c = if command in c.config.unacked_commands, do: c, else: say(c, ack(from, command, result))
      Enum.reduce(afterwards, c, &say(&2, &1))
    end
  end

  defp ack({sysid, compid}, command, result),
    do: %M.CommandAck{command: command, result: result, target_system: sysid, target_component: compid}

  # MAV_CMD_COMPONENT_ARM_DISARM
  defp run_command(c, 400, [p1, p2 | _], _), do: if(round(p1) == 1, do: Modes.arm(c, p2 == @force_arm), else: Modes.disarm(c, p2 == @force_arm))

  # MAV_CMD_DO_SET_MODE: p1 has MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, p2 is the custom mode.
  defp run_command(c, 176, [_p1, p2 | _], _), do: Modes.set_mode(c, round(p2))

  # MAV_CMD_NAV_TAKEOFF: p7 metres above home, in GUIDED, armed, on the
  # ground, and up (ArduCopter's do_user_takeoff refuses a take-off downwards).
  defp run_command(c, 22, params, position) do
    alt = takeoff_alt(c, params, position)

    cond do
      c.mode != :guided or not c.armed -> {@failed, c}
      in_air?(c) -> {@failed, c}
      alt <= c.alt -> {@failed, c}
      true -> {@accepted, Flight.start_takeoff(c, alt)}
    end
  end

  defp run_command(c, 21, _params, _), do: Modes.set_mode_named(c, :land)
  defp run_command(c, 20, _params, _), do: Modes.set_mode_named(c, :rtl)

  # MAV_CMD_MISSION_START: to AUTO (ArduPilot switches itself), from p1 when given.
  defp run_command(c, 300, [p1 | _], _) do
    n = length(MissionServer.items(c.missions))

    cond do
      n == 0 ->
        {@failed, text(c, 4, "Mission: no mission")}

      c.armed and not in_air?(c) and not Mission.starts_with_takeoff?(c) ->
        {@failed, text(c, 2, "Auto: Missing Takeoff Cmd")}

      c.mode == :auto and c.mission_state == 3 ->
        {@accepted, c}

      c.mode == :auto ->
        first = round(p1)
        {@accepted, Mission.start_item(c, if(first >= 1 and first <= n, do: first, else: c.resume || 1))}

      true ->
        first = round(p1)
        c = if first >= 1 and first <= n, do: %{c | resume: first}, else: c
        Modes.set_mode_named(c, :auto)
    end
  end

  # MAV_CMD_DO_SET_MISSION_CURRENT
  defp run_command(c, 224, [p1 | _], _) do
    seq = round(p1)
    if seq >= 0 and seq <= length(MissionServer.items(c.missions)), do: {@accepted, Mission.set_current(c, seq)}, else: {@denied, c}
  end

  # MAV_CMD_DO_SET_HOME: p1 = 1 here, else the given point (denied off the
  # map, as ArduPilot's check of a command's latitude and longitude does).
  defp run_command(c, 179, [p1 | _] = params, position) do
    point = command_point(params, position)

    cond do
      not ready?(c) -> {@failed, c}
      round(p1) == 1 -> home_set_after_ack(c, position(c))
      not on_map?(point) -> {@denied, c}
      true -> home_set_after_ack(c, point)
    end
  end

  # MAV_CMD_DO_CHANGE_SPEED: p2 metres per second (-1: no change).
  defp run_command(c, 178, [_p1, p2 | _], _) when p2 > 0, do: {@accepted, %{c | speed: p2 * 1.0}}
  defp run_command(c, 178, _params, _), do: {@accepted, c}

  # MAV_CMD_DO_REPOSITION: fly to a point in GUIDED (bit 0 of p2: switch to GUIDED first).
  defp run_command(c, 192, [p1, p2 | _] = params, position) do
    {c, ok?} =
      if c.mode != :guided and (round(p2) &&& 1) == 1 do
        {result, c} = Modes.set_mode_named(c, :guided)
        {c, result == @accepted}
      else
        {c, c.mode == :guided}
      end

    point = command_point(params, position)

    with true <- ok? and on_map?(point), {:ok, c} <- Flight.guided_goto(c, point.lat, point.lon, point.alt) do
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

  # MAV_CMD_REQUEST_MESSAGE, MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: the
  # message after the COMMAND_ACK. The older MAV_CMD_GET_HOME_POSITION sends
  # HOME_POSITION at once, before it (both seen on ArduCopter SITL): a ground
  # station that waits for the ACK before it looks for the message misses it
  # from one, not from the other.
  defp run_command(c, 512, [p1 | _], _), do: request_message(c, round(p1))
  defp run_command(c, 520, _params, _), do: request_message(c, 148)

  defp run_command(c, 410, _params, _) do
    case request_message(c, 242) do
      {@accepted, c, [home]} -> {@accepted, say(c, home)}
      refused -> refused
    end
  end

  # MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN (p1 = 1: reboot), refused while armed.
  defp run_command(c, 246, [p1 | _], _) do
    cond do
      c.armed -> {@failed, c}
      round(p1) == 1 -> {@accepted, %{c | out: [{:reboot, nil} | c.out]}}
      true -> {@unsupported, c}
    end
  end

  # Camera commands to the autopilot (ArduPilot's camera library).
  defp run_command(c, command, params, _) when command in [203, 206, 2000, 2001], do: Camera.command(c, command, params)

  defp run_command(c, _command, _params, _), do: {@unsupported, c}

  defp request_message(c, msgid) do
    case Streams.message(c, msgid) do
      nil -> {@denied, c}
      message -> {@accepted, c, [message]}
    end
  end

  # A new home, its HOME_POSITION after the COMMAND_ACK.
  defp home_set_after_ack(c, point) do
    c = put_home(c, point)
    {@accepted, c, [Streams.message(c, 242)]}
  end

  # A COMMAND_INT carries its point in x/y/z (degE7, metres in its frame);
  # a COMMAND_LONG in p5..p7 (degrees, metres AMSL).
  defp command_point(_params, {frame, x, y, z}), do: %{lat: x / 1.0e7, lon: y / 1.0e7, alt: {frame, z}}

  defp command_point([_, _, _, _, lat, lon, alt], nil), do: %{lat: lat, lon: lon, alt: {0, alt}}

  defp on_map?(%{lat: lat, lon: lon}), do: is_number(lat) and is_number(lon) and lat >= -90 and lat <= 90 and lon >= -180 and lon <= 180

  defp takeoff_alt(c, _params, {frame, _x, _y, z}), do: target_alt(c, frame, z)
  defp takeoff_alt(c, params, nil), do: home_alt(c) + List.last(params)
end
