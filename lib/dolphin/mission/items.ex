defmodule Dolphin.Mission.Items do
  @moduledoc false
  # Turns a mission's commands into MISSION_ITEM_INT structs: resolves the
  # relative moves and surveys against home and the previous point, numbers the
  # items from 0 (home) and checks the jump targets. The table of choices is in
  # Dolphin.Mission's moduledoc.

  alias Dolphin.Geo
  alias Dolphin.Geo.Location
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Mission
  alias Dolphin.Mission.{Command, Survey}

  commands = [
    :mav_cmd_nav_waypoint,
    :mav_cmd_nav_loiter_unlim,
    :mav_cmd_nav_loiter_turns,
    :mav_cmd_nav_loiter_time,
    :mav_cmd_nav_land,
    :mav_cmd_nav_takeoff,
    :mav_cmd_nav_delay,
    :mav_cmd_do_jump,
    :mav_cmd_do_change_speed,
    :mav_cmd_image_start_capture,
    :mav_cmd_image_stop_capture,
    :mav_cmd_do_land_start
  ]

  # Command numbers from the dialect's MAV_CMD enum, at compile time.
  @cmd Map.new(commands, fn name ->
         {:ok, n} = M.enum_value(:mav_cmd, name)
         {name, n}
       end)

  {:ok, global_int} = M.enum_value(:mav_frame, :mav_frame_global_int)
  {:ok, mission_frame} = M.enum_value(:mav_frame, :mav_frame_mission)
  {:ok, relative_int} = M.enum_value(:mav_frame, :mav_frame_global_relative_alt_int)
  @relative_int relative_int
  @global_int global_int
  @mission_frame mission_frame

  @doc false
  def frames, do: %{global_int: @global_int, mission: @mission_frame}

  @doc false
  def command_number(name), do: Map.fetch!(@cmd, name)

  # `airframe` (nil: a copter's items) changes what some commands are: a
  # plane's landing starts its landing sequence (DO_LAND_START, which RTL and
  # DO_LAND_START jump to); a submarine's heights are depths in
  # GLOBAL_RELATIVE_ALT_INT (ArduSub skips GLOBAL_INT items, "Bad alt
  # frame", and any height above its home, the surface).
  @spec to_items(Mission.t(), atom() | nil) :: [struct()]
  def to_items(%Mission{} = mission, airframe \\ nil) do
    home = home!(mission)
    state = %{home: home, prev: home, photo: 0, airframe: airframe}

    {items, _state} = Enum.flat_map_reduce(mission.commands, state, &items/2)
    # Item 0 is home: ArduPilot accepts it and keeps its own.
    items = [nav(:mav_cmd_nav_waypoint, home, {0, 0, 0, 0}) | items] |> Enum.with_index() |> Enum.map(fn {item, seq} -> %{item | seq: seq} end)
    check_jumps!(mission, items)
    if Dolphin.Airframe.heights(airframe) == :depth, do: depths!(mission, items, home), else: items
  end

  # Item 0 stays home as given (ArduPilot keeps its own); every other
  # position relative to it, never above the surface.
  defp depths!(mission, [home_item | items], home) do
    [
      home_item
      | Enum.map(items, fn
          %{frame: @global_int} = item ->
            depth = item.z - home.h

            if depth > 0.5,
              do:
                raise(
                  ArgumentError,
                  "mission #{inspect(mission.name)}: item #{item.seq} is #{Float.round(depth, 1)} m above the surface; a submarine's heights are depths, at most 0 (the surface, its home's height #{home.h} m)"
                )

            %{item | frame: @relative_int, z: min(depth, 0.0)}

          item ->
            item
        end)
    ]
  end

  @doc false
  # Which items each command gave: `{kind, first seq, count}` in order (home,
  # item 0, excluded). Dolphin.Mission.Resume needs a survey's passes.
  @spec spans(Mission.t()) :: [{atom(), pos_integer(), non_neg_integer()}]
  def spans(%Mission{} = mission, airframe \\ nil) do
    home = home!(mission)

    {spans, {_state, _next}} =
      Enum.map_reduce(mission.commands, {%{home: home, prev: home, photo: 0, airframe: airframe}, 1}, fn %Command{kind: kind} = c, {state, next} ->
        {items, state} = items(c, state)
        {{kind, next, length(items)}, {state, next + length(items)}}
      end)

    spans
  end

  # Without a home, the original plugin used the first absolute position of the mission.
  defp home!(%Mission{home: %Location{} = home}), do: home

  defp home!(%Mission{} = mission) do
    Enum.find_value(mission.commands, fn
      %Command{args: args} -> match?(%Location{}, args[:position]) && args[:position]
    end) ||
      raise ArgumentError,
            "mission #{inspect(mission.name)} has no home, and no position of its own to take for one: give it one with `home location(LAT, LON, ALT)` in its block"
  end

  defp items(%Command{kind: kind, args: a}, state) do
    case kind do
      :go_pos ->
        goto(waypoint(a[:position], 0), a[:position], state)

      :take_off ->
        goto(nav(:mav_cmd_nav_takeoff, a[:position], {a[:pitch], 0, 0, :nan}), a[:position], state)

      :take_off_with_yaw ->
        goto(nav(:mav_cmd_nav_takeoff, a[:position], {a[:pitch], 0, 0, a[:yaw]}), a[:position], state)

      :loiter_pos ->
        goto(unlim(a[:position], a[:radius]), a[:position], state)

      :loiter_turns ->
        goto(turns(a[:position], a[:turns], a[:radius]), a[:position], state)

      :loiter_time ->
        goto(time(a[:position], a[:time], a[:radius]), a[:position], state)

      :landing_point ->
        goto(landing(state, a[:position], a[:yaw], a[:land_mode]), a[:position], state)

      :move ->
        p = relative(state.prev, a)
        goto(waypoint(p, 0), p, state)

      :move_from_home ->
        p = relative(state.home, a)
        goto(waypoint(p, 0), p, state)

      :move_and_loiter_pos ->
        p = relative(state.prev, a)
        goto(unlim(p, a[:radius]), p, state)

      :move_and_loiter_from_home ->
        p = relative(state.home, a)
        goto(unlim(p, a[:radius]), p, state)

      :move_and_loiter_turns ->
        p = relative(state.prev, a)
        goto(turns(p, a[:turns], a[:radius]), p, state)

      :move_and_loiter_turns_from_home ->
        p = relative(state.home, a)
        goto(turns(p, a[:turns], a[:radius]), p, state)

      :move_and_loiter_time ->
        p = relative(state.prev, a)
        goto(time(p, a[:time], a[:radius]), p, state)

      :move_and_loiter_time_from_home ->
        p = relative(state.home, a)
        goto(time(p, a[:time], a[:radius]), p, state)

      :return_home ->
        p = Location.at_height(state.home, state.prev.h)
        goto(waypoint(p, 0), p, state)

      :return_home_and_loiter ->
        p = Location.at_height(state.home, state.prev.h)
        goto(unlim(p, a[:radius]), p, state)

      :return_home_and_land ->
        goto(landing(state, state.home, a[:yaw], a[:land_mode]), state.home, state)

      :altitude ->
        p = Location.at_height(state.prev, a[:altitude])
        goto(waypoint(p, 0), p, state)

      :survey_area ->
        base = if a[:base] == :previous, do: state.prev, else: a[:base]
        points = Survey.waypoints(base, a[:length], a[:width], a[:spacing], a[:direction])
        {Enum.map(points, &waypoint(&1, 0)), %{state | prev: List.last(points)}}

      :speed ->
        # Throttle -1: no change.
        {[command(:mav_cmd_do_change_speed, {a[:speed_type], a[:speed], -1, 0})], state}

      :delay ->
        # Hours, minutes, seconds of day -1: a plain delay.
        {[command(:mav_cmd_nav_delay, {a[:seconds], -1, -1, -1})], state}

      :capture_photo ->
        # One picture from every camera (param 1 = 0), numbered from 1 as the
        # spec asks of single captures.
        photo = state.photo + 1
        {[command(:mav_cmd_image_start_capture, {0, 0, 1, photo})], %{state | photo: photo}}

      :capture_several_photos ->
        {[command(:mav_cmd_image_start_capture, {0, a[:interval], a[:count], 0})], state}

      :capture_until_stop ->
        {[command(:mav_cmd_image_start_capture, {0, a[:interval], 0, 0})], state}

      :stop_capturing ->
        # Params 2-4 are reserved (NaN in the spec), but ArduPilot refuses NaN there.
        {[command(:mav_cmd_image_stop_capture, {0, 0, 0, 0})], state}

      :jump_to_item ->
        {[command(:mav_cmd_do_jump, {a[:item], a[:repeat], 0, 0})], state}

      :item ->
        [p1, p2, p3, p4] = a[:params]

        item = %M.MissionItemInt{
          base()
          | command: a[:command],
            frame: a[:frame],
            param1: p1,
            param2: p2,
            param3: p3,
            param4: p4,
            x: a[:x],
            y: a[:y],
            z: a[:z],
            autocontinue: a[:autocontinue]
        }

        {[item], state}
    end
  end

  defp goto(items, position, state), do: {List.wrap(items), %{state | prev: position}}

  defp relative(from, a), do: Geo.offset(from, a[:north], a[:east], a[:up])

  defp waypoint(p, hold), do: nav(:mav_cmd_nav_waypoint, p, {hold, 0, 0, :nan})
  # Param 4 (yaw) of the loiters must not be NaN for ArduPilot, which only
  # accepts NaN in param 4 of WAYPOINT, TAKEOFF and LAND.
  defp unlim(p, radius), do: nav(:mav_cmd_nav_loiter_unlim, p, {0, 0, radius, 0})
  defp turns(p, turns, radius), do: nav(:mav_cmd_nav_loiter_turns, p, {turns, 0, radius, 0})
  defp time(p, seconds, radius), do: nav(:mav_cmd_nav_loiter_time, p, {seconds, 0, radius, 0})
  defp land(p, yaw, mode), do: nav(:mav_cmd_nav_land, p, {0, mode, 0, yaw})

  # A landing as the airframe makes one: a plane's is a landing sequence —
  # DO_LAND_START where it starts, a waypoint on the approach in line with
  # the way it comes (from the previous point), then NAV_LAND.
  defp landing(%{airframe: airframe, prev: prev}, p, yaw, mode) do
    for command <- Dolphin.Airframe.of(airframe).landing_commands() do
      case command do
        :mav_cmd_nav_land -> land(p, yaw, mode)
        {:approach, metres, slope_deg} -> waypoint(approach(prev, p, metres, slope_deg), 0)
        {start, {:approach, metres, slope_deg}} -> nav(start, approach(prev, p, metres, slope_deg), {0, 0, 0, 0})
      end
    end
  end

  # `metres` before `p` on the line from `from` (from the south when `from`
  # is `p`), high enough to glide down to it at `slope_deg`.
  defp approach(from, p, metres, slope_deg) do
    {n, e} = Geo.ne_offset(p, from)
    d = :math.sqrt(n * n + e * e)
    {un, ue} = if d < 1.0, do: {-1.0, 0.0}, else: {n / d, e / d}
    Geo.offset(p, un * metres, ue * metres, metres * :math.tan(slope_deg * :math.pi() / 180))
  end

  defp nav(name, %Location{} = p, params) do
    %{with_params(base(), params) | command: Map.fetch!(@cmd, name), frame: @global_int, x: e7(p.lat), y: e7(p.lon), z: p.h / 1}
  end

  defp command(name, params), do: %{with_params(base(), params) | command: Map.fetch!(@cmd, name), frame: @mission_frame}

  defp base, do: %M.MissionItemInt{autocontinue: 1, current: 0, mission_type: 0, z: 0.0}

  defp with_params(item, {p1, p2, p3, p4}), do: %{item | param1: f(p1), param2: f(p2), param3: f(p3), param4: f(p4)}

  defp f(:nan), do: :nan
  defp f(n), do: n / 1

  defp e7(degrees), do: round(degrees * 1.0e7)

  defp check_jumps!(mission, items) do
    last = length(items) - 1
    jump = Map.fetch!(@cmd, :mav_cmd_do_jump)

    for %{command: ^jump, param1: target, seq: seq} <- items, round(target) > last do
      raise ArgumentError,
            "mission #{inspect(mission.name)}: item #{seq} jumps to item #{round(target)}, which does not exist (items run from 1 to #{last})"
    end

    :ok
  end
end
