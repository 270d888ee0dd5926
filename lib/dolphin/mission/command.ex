defmodule Dolphin.Mission.Command do
  @moduledoc """
  The mission commands of the report's Table 2, as values: each function
  returns a `%Dolphin.Mission.Command{}` (its `kind` and its arguments, as
  written, defaults filled in) that `Dolphin.Mission.new/2` puts in a mission.
  Nothing is computed here: relative moves and surveys are resolved against
  the mission's home and previous point only when the mission is turned into
  items (`Dolphin.Mission.to_items/1`).

  These are the words of the `mission "name" do ... end` block
  (`Dolphin.DSL.Mission`); without the macro they read:

      iex> alias Dolphin.Mission.Command, as: C
      iex> home = Dolphin.Geo.location(40.444233, -7.375234, 820)
      iex> m = Dolphin.Mission.new("Survey Area", [C.home(home), C.take_off(Dolphin.Geo.Location.at_height(home, 1200)), C.move(100, 200, 100)])
      iex> Enum.map(m.commands, &inspect/1)
      ["take_off(location(40.444233, -7.375234, 1200.0), 15)", "move(100, 200, 100)"]

  Every function taking a position accepts a `Dolphin.Geo.Location` or
  `lat, lon, h` (degrees, degrees, metres above mean sea level). Numbers are
  metres, seconds (as in the report: `delay 30` is thirty seconds — a
  duration value like `seconds(30)` is in milliseconds and does not belong
  here) and degrees. Yaw angles may be `:nan` ("keep the current heading
  mode"), the report's `NaN`. Loiter radii are positive for clockwise, negative
  for counter-clockwise circles.

  Caller mistakes (a string for a number, an unknown direction, a negative
  photo count...) raise `ArgumentError` naming the command and the value.

  This module is long because it is the whole vocabulary in one place: one
  documented function (with its `lat, lon, h` twin) per command of Table 2,
  which is what `h take_off` shows in the console; it computes nothing.
  """

  alias Dolphin.Geo.Location

  @enforce_keys [:kind, :args]
  defstruct [:kind, :args]

  @typedoc "A command: its kind (the DSL word) and its arguments in the report's order."
  @type t :: %__MODULE__{kind: atom(), args: keyword()}

  @type position :: Location.t()
  @type yaw :: number() | :nan
  @type direction :: :north_west | :north_east | :south_west | :south_east

  @default_radius 15
  @default_pitch 15
  @default_spacing 50
  @default_direction :north_west
  @default_interval 2

  @directions [:north_west, :north_east, :south_west, :south_east]
  @land_modes %{disabled: 0, opportunistic: 1, required: 2}
  @speed_types %{airspeed: 0, air_speed: 0, ground_speed: 1, groundspeed: 1, climb_speed: 2, descent_speed: 3}

  # --- mission attributes ---------------------------------------------------

  @doc """
  Sets the mission's name (`name "Survey Area"`).

      name "Survey Area"
  """
  @spec name(String.t()) :: t()
  def name(name) when is_binary(name), do: cmd(:name, name: name)
  def name(other), do: raise(ArgumentError, "name/1: a mission's name is a string, got: #{inspect(other)}")

  @doc """
  Sets the home position: item 0 of the upload (ArduPilot keeps its own home
  there), the origin of the `..._from_home` moves and the target of the
  `return_home...` commands. Also `home(lat, lon, h)`.

      home location(40.444233, -7.375234, 820)
  """
  @spec home(position()) :: t()
  def home(position), do: cmd(:home, position: pos!(:home, position))

  @doc """
  `home/1` with the position as `lat, lon, h`.

      home 40.444233, -7.375234, 820
  """
  @spec home(number(), number(), number()) :: t()
  def home(lat, lon, h), do: cmd(:home, position: pos!(:home, lat, lon, h))

  # --- absolute positions ---------------------------------------------------

  @doc """
  Goes to a position (a waypoint). Also `go_pos(lat, lon, h)`.

      go_pos location(40.4451, -7.3752, 1200)
  """
  @spec go_pos(position()) :: t()
  def go_pos(position), do: cmd(:go_pos, position: pos!(:go_pos, position))

  @doc """
  `go_pos/1` with the position as `lat, lon, h`.

      go_pos 40.4451, -7.3752, 1200
  """
  @spec go_pos(number(), number(), number()) :: t()
  def go_pos(lat, lon, h), do: cmd(:go_pos, position: pos!(:go_pos, lat, lon, h))

  @doc """
  Takes off and climbs to the position's height; `pitch` (degrees, default
  15) only matters to fixed-wing aircraft. Also `take_off(lat, lon, h, pitch \\\\ 15)`.

      take_off location(40.444233, -7.375234, 1200)      # pitch 15
  """
  @spec take_off(position(), number()) :: t()
  def take_off(position, pitch \\ @default_pitch)
  def take_off(%Location{} = p, pitch), do: cmd(:take_off, position: p, pitch: num!(:take_off, :pitch, pitch))
  def take_off(lat, lon) when is_number(lat) and is_number(lon), do: arity_error(:take_off, [lat, lon])
  def take_off(other, _pitch), do: pos!(:take_off, other)

  @doc """
  `take_off/2` with the position as `lat, lon, h`.

      take_off 40.444233, -7.375234, 1200, 15
  """
  @spec take_off(number(), number(), number(), number()) :: t()
  def take_off(lat, lon, h, pitch \\ @default_pitch),
    do: cmd(:take_off, position: pos!(:take_off, lat, lon, h), pitch: num!(:take_off, :pitch, pitch))

  @doc """
  Takes off like `take_off/2`, turning to `yaw` degrees (`:nan`, the default,
  keeps the heading). The arguments are in the original plugin's order:
  position, pitch, yaw. Also `take_off_with_yaw(lat, lon, h, pitch, yaw \\\\ :nan)`.

      take_off_with_yaw location(40.444233, -7.375234, 1200), 15, 90
  """
  @spec take_off_with_yaw(position(), number(), yaw()) :: t()
  def take_off_with_yaw(position, pitch, yaw \\ :nan)

  def take_off_with_yaw(%Location{} = p, pitch, yaw),
    do: cmd(:take_off_with_yaw, position: p, pitch: num!(:take_off_with_yaw, :pitch, pitch), yaw: yaw!(:take_off_with_yaw, yaw))

  def take_off_with_yaw(other, _pitch, _yaw), do: pos!(:take_off_with_yaw, other)

  @doc """
  `take_off_with_yaw/3` with the position as `lat, lon, h`.

      take_off_with_yaw 40.444233, -7.375234, 1200, 15, 90
  """
  @spec take_off_with_yaw(number(), number(), number(), number(), yaw()) :: t()
  def take_off_with_yaw(lat, lon, h, pitch, yaw \\ :nan),
    do:
      cmd(:take_off_with_yaw,
        position: pos!(:take_off_with_yaw, lat, lon, h),
        pitch: num!(:take_off_with_yaw, :pitch, pitch),
        yaw: yaw!(:take_off_with_yaw, yaw)
      )

  @doc """
  Goes to a position and circles it with `radius` metres (default 15) for ever. Also `loiter_pos(lat, lon, h, radius \\\\ 15)`.

      loiter_pos location(40.4451, -7.3752, 1200), 50
  """
  @spec loiter_pos(position(), number()) :: t()
  def loiter_pos(position, radius \\ @default_radius)
  def loiter_pos(%Location{} = p, radius), do: cmd(:loiter_pos, position: p, radius: num!(:loiter_pos, :radius, radius))
  def loiter_pos(lat, lon) when is_number(lat) and is_number(lon), do: arity_error(:loiter_pos, [lat, lon])
  def loiter_pos(other, _radius), do: pos!(:loiter_pos, other)

  @doc """
  `loiter_pos/2` with the position as `lat, lon, h`.

      loiter_pos 40.4451, -7.3752, 1200, 50
  """
  @spec loiter_pos(number(), number(), number(), number()) :: t()
  def loiter_pos(lat, lon, h, radius \\ @default_radius),
    do: cmd(:loiter_pos, position: pos!(:loiter_pos, lat, lon, h), radius: num!(:loiter_pos, :radius, radius))

  @doc """
  Goes to a position and circles it `turns` times. Also `loiter_turns(lat, lon, h, turns, radius \\\\ 15)`.

      loiter_turns location(40.4451, -7.3752, 1200), 3
  """
  @spec loiter_turns(position(), number(), number()) :: t()
  def loiter_turns(position, turns, radius \\ @default_radius)

  def loiter_turns(%Location{} = p, turns, radius),
    do: cmd(:loiter_turns, position: p, turns: count!(:loiter_turns, :turns, turns), radius: num!(:loiter_turns, :radius, radius))

  def loiter_turns(other, _turns, _radius), do: pos!(:loiter_turns, other)

  @doc """
  `loiter_turns/3` with the position as `lat, lon, h`.

      loiter_turns 40.4451, -7.3752, 1200, 3
  """
  @spec loiter_turns(number(), number(), number(), number(), number()) :: t()
  def loiter_turns(lat, lon, h, turns, radius \\ @default_radius),
    do:
      cmd(:loiter_turns,
        position: pos!(:loiter_turns, lat, lon, h),
        turns: count!(:loiter_turns, :turns, turns),
        radius: num!(:loiter_turns, :radius, radius)
      )

  @doc """
  Goes to a position and circles it for `time` seconds. Also `loiter_time(lat, lon, h, time, radius \\\\ 15)`.

      loiter_time location(40.4451, -7.3752, 1200), 30
  """
  @spec loiter_time(position(), number(), number()) :: t()
  def loiter_time(position, time, radius \\ @default_radius)

  def loiter_time(%Location{} = p, time, radius),
    do: cmd(:loiter_time, position: p, time: secs!(:loiter_time, :time, time), radius: num!(:loiter_time, :radius, radius))

  def loiter_time(other, _time, _radius), do: pos!(:loiter_time, other)

  @doc """
  `loiter_time/3` with the position as `lat, lon, h`.

      loiter_time 40.4451, -7.3752, 1200, 30
  """
  @spec loiter_time(number(), number(), number(), number(), number()) :: t()
  def loiter_time(lat, lon, h, time, radius \\ @default_radius),
    do:
      cmd(:loiter_time,
        position: pos!(:loiter_time, lat, lon, h),
        time: secs!(:loiter_time, :time, time),
        radius: num!(:loiter_time, :radius, radius)
      )

  @doc """
  Lands at a position, facing `yaw` degrees (`:nan`, the default, lets the
  vehicle choose), with a precision-landing mode: `0`/`:disabled` (default),
  `1`/`:opportunistic`, `2`/`:required`. Also
  `landing_point(lat, lon, h, yaw \\\\ :nan, land_mode \\\\ 0)`; `h` is the
  ground's height above mean sea level.

      landing_point location(40.4451, -7.3752, 820)
  """
  @spec landing_point(position()) :: t()
  def landing_point(%Location{} = p), do: landing(p, :nan, 0)
  def landing_point(other), do: pos!(:landing_point, other)

  @doc """
  `landing_point/1` facing `yaw` degrees.

      landing_point location(40.4451, -7.3752, 820), 90
  """
  @spec landing_point(position(), yaw()) :: t()
  def landing_point(%Location{} = p, yaw), do: landing(p, yaw, 0)
  def landing_point(lat, lon) when is_number(lat) and is_number(lon), do: arity_error(:landing_point, [lat, lon])
  def landing_point(other, _yaw), do: pos!(:landing_point, other)

  @doc """
  `landing_point/1` with a yaw and a precision-landing mode, or with the position as `lat, lon, h`.

      landing_point location(40.4451, -7.3752, 820), :nan, :opportunistic
      landing_point 40.4451, -7.3752, 820
  """
  @spec landing_point(position() | number(), yaw() | number(), non_neg_integer() | atom() | number()) :: t()
  def landing_point(%Location{} = p, yaw, land_mode), do: landing(p, yaw, land_mode)
  def landing_point(lat, lon, h), do: landing(pos!(:landing_point, lat, lon, h), :nan, 0)

  @doc """
  `landing_point/3` with the position as `lat, lon, h`.

      landing_point 40.4451, -7.3752, 820, 90, :required
  """
  @spec landing_point(number(), number(), number(), yaw(), non_neg_integer() | atom()) :: t()
  def landing_point(lat, lon, h, yaw, land_mode \\ 0), do: landing(pos!(:landing_point, lat, lon, h), yaw, land_mode)

  defp landing(p, yaw, land_mode),
    do: cmd(:landing_point, position: p, yaw: yaw!(:landing_point, yaw), land_mode: land_mode!(:landing_point, land_mode))

  # --- relative moves -------------------------------------------------------

  @doc """
  Moves `north`, `east`, `up` metres from the previous point of the mission (home at first).

      move 100, 200, 100
  """
  @spec move(number(), number(), number()) :: t()
  def move(north, east, up), do: cmd(:move, neu(:move, north, east, up))

  @doc """
  Moves to `north`, `east`, `up` metres from home.

      move_from_home 0, 500, 380
  """
  @spec move_from_home(number(), number(), number()) :: t()
  def move_from_home(north, east, up), do: cmd(:move_from_home, neu(:move_from_home, north, east, up))

  @doc """
  Moves like `move/3`, then circles the point for ever (radius default 15 m).

      move_and_loiter_pos 200, 100, -20, 50
  """
  @spec move_and_loiter_pos(number(), number(), number(), number()) :: t()
  def move_and_loiter_pos(north, east, up, radius \\ @default_radius),
    do: cmd(:move_and_loiter_pos, neu(:move_and_loiter_pos, north, east, up) ++ [radius: num!(:move_and_loiter_pos, :radius, radius)])

  @doc """
  Moves like `move/3`, then circles the point `turns` times.

      move_and_loiter_turns 200, 100, 0, 3
  """
  @spec move_and_loiter_turns(number(), number(), number(), number(), number()) :: t()
  def move_and_loiter_turns(north, east, up, turns, radius \\ @default_radius), do: loiter_turns_cmd(:move_and_loiter_turns, north, east, up, turns, radius)

  @doc """
  Moves like `move/3`, then circles the point for `time` seconds.

      move_and_loiter_time 200, 100, 0, 30
  """
  @spec move_and_loiter_time(number(), number(), number(), number(), number()) :: t()
  def move_and_loiter_time(north, east, up, time, radius \\ @default_radius), do: loiter_time_cmd(:move_and_loiter_time, north, east, up, time, radius)

  @doc """
  Moves like `move_from_home/3`, then circles the point for ever.

      move_and_loiter_from_home 500, 0, 380
  """
  @spec move_and_loiter_from_home(number(), number(), number(), number()) :: t()
  def move_and_loiter_from_home(north, east, up, radius \\ @default_radius),
    do:
      cmd(
        :move_and_loiter_from_home,
        neu(:move_and_loiter_from_home, north, east, up) ++ [radius: num!(:move_and_loiter_from_home, :radius, radius)]
      )

  @doc """
  Moves like `move_from_home/3`, then circles the point `turns` times.

      move_and_loiter_turns_from_home 500, 0, 380, 3
  """
  @spec move_and_loiter_turns_from_home(number(), number(), number(), number(), number()) :: t()
  def move_and_loiter_turns_from_home(north, east, up, turns, radius \\ @default_radius),
    do: loiter_turns_cmd(:move_and_loiter_turns_from_home, north, east, up, turns, radius)

  @doc """
  Moves like `move_from_home/3`, then circles the point for `time` seconds.

      move_and_loiter_time_from_home 500, 0, 380, 30
  """
  @spec move_and_loiter_time_from_home(number(), number(), number(), number(), number()) :: t()
  def move_and_loiter_time_from_home(north, east, up, time, radius \\ @default_radius),
    do: loiter_time_cmd(:move_and_loiter_time_from_home, north, east, up, time, radius)

  defp loiter_turns_cmd(kind, north, east, up, turns, radius),
    do: cmd(kind, neu(kind, north, east, up) ++ [turns: count!(kind, :turns, turns), radius: num!(kind, :radius, radius)])

  defp loiter_time_cmd(kind, north, east, up, time, radius),
    do: cmd(kind, neu(kind, north, east, up) ++ [time: secs!(kind, :time, time), radius: num!(kind, :radius, radius)])

  # --- home -------------------------------------------------------------------

  @doc """
  Flies back over home, at the height of the previous point, and holds there.

      return_home()
  """
  @spec return_home() :: t()
  def return_home, do: cmd(:return_home, [])

  @doc """
  Flies back over home, at the height of the previous point, and circles it for ever.

      return_home_and_loiter 30
  """
  @spec return_home_and_loiter(number()) :: t()
  def return_home_and_loiter(radius \\ @default_radius), do: cmd(:return_home_and_loiter, radius: num!(:return_home_and_loiter, :radius, radius))

  @doc """
  Flies back to home and lands there (yaw and precision-landing mode as in `landing_point/3`).

      return_home_and_land()
  """
  @spec return_home_and_land(yaw(), non_neg_integer() | atom()) :: t()
  def return_home_and_land(yaw \\ :nan, land_mode \\ 0),
    do: cmd(:return_home_and_land, yaw: yaw!(:return_home_and_land, yaw), land_mode: land_mode!(:return_home_and_land, land_mode))

  # --- settings and timing --------------------------------------------------

  @doc """
  Changes the speed, in m/s. `speed_type`: `0`/`:airspeed` (the default),
  `1`/`:ground_speed`, `2`/`:climb_speed`, `3`/`:descent_speed`.

      speed 12                  # airspeed, m/s
  """
  @spec speed(number(), non_neg_integer() | atom()) :: t()
  def speed(new_speed, speed_type \\ 0), do: cmd(:speed, speed: num!(:speed, :speed, new_speed), speed_type: speed_type!(speed_type))

  @doc """
  Climbs or descends, over the previous point, to `altitude` metres above mean sea level.

      altitude 1000             # metres above mean sea level
  """
  @spec altitude(number()) :: t()
  def altitude(altitude), do: cmd(:altitude, altitude: num!(:altitude, :altitude, altitude))

  @doc """
  Holds the mission for `seconds` seconds.

      delay 30                  # seconds
  """
  @spec delay(number()) :: t()
  def delay(seconds), do: cmd(:delay, seconds: secs!(:delay, :seconds, seconds))

  @doc """
  Surveys a `length` × `width` metres rectangle with a lawnmower pattern (see
  `Dolphin.Mission.Survey`): `length` runs north–south, along the passes;
  `width` runs east–west, across them; passes are at most `spacing` metres
  apart (default 50); the rectangle lies to the `direction` of its base
  corner (`:north_west`, the default, `:north_east`, `:south_west`,
  `:south_east`; the report's strings `"NORTH_EAST"`... are accepted).

  The base corner is the previous point of the mission, or the given
  position: `survey_area(position, length, width, spacing \\\\ 50, direction \\\\ :north_west)`,
  also with `lat, lon, h` in place of the position. The survey flies at the
  base's height.

      survey_area 3000, 10000, 500, :north_east
  """
  @spec survey_area(number(), number()) :: t()
  def survey_area(length, width), do: survey(:previous, length, width, @default_spacing, @default_direction)

  @doc """
  `survey_area/2` from a given base corner, or with a spacing.

      survey_area location(40.4451, -7.3752, 1200), 3000, 10000
      survey_area 3000, 10000, 500
  """
  @spec survey_area(number() | position(), number(), number()) :: t()
  def survey_area(%Location{} = p, length, width), do: survey(p, length, width, @default_spacing, @default_direction)
  def survey_area(length, width, spacing), do: survey(:previous, length, width, spacing, @default_direction)

  @doc """
  `survey_area/2` from a given base corner with a spacing, or with a spacing and a direction.

      survey_area location(40.4451, -7.3752, 1200), 3000, 10000, 500
      survey_area 3000, 10000, 500, :north_east
  """
  @spec survey_area(number() | position(), number(), number(), number() | direction()) :: t()
  def survey_area(%Location{} = p, length, width, spacing), do: survey(p, length, width, spacing, @default_direction)
  def survey_area(length, width, spacing, direction), do: survey(:previous, length, width, spacing, direction)

  @doc """
  `survey_area/2` from a given base corner with a spacing and a direction, or from `lat, lon, h`.

      survey_area location(40.4451, -7.3752, 1200), 3000, 10000, 500, :south_east
      survey_area 40.4451, -7.3752, 1200, 3000, 10000
  """
  @spec survey_area(number() | position(), number(), number(), number(), number() | direction()) :: t()
  def survey_area(%Location{} = p, length, width, spacing, direction), do: survey(p, length, width, spacing, direction)
  def survey_area(lat, lon, h, length, width), do: survey(pos!(:survey_area, lat, lon, h), length, width, @default_spacing, @default_direction)

  @doc """
  `survey_area/2` from `lat, lon, h` with a spacing.

      survey_area 40.4451, -7.3752, 1200, 3000, 10000, 500
  """
  @spec survey_area(number(), number(), number(), number(), number(), number() | direction()) :: t()
  def survey_area(lat, lon, h, length, width, spacing), do: survey(pos!(:survey_area, lat, lon, h), length, width, spacing, @default_direction)

  @doc """
  `survey_area/2` from `lat, lon, h` with a spacing and a direction.

      survey_area 40.4451, -7.3752, 1200, 3000, 10000, 500, :north_east
  """
  @spec survey_area(number(), number(), number(), number(), number(), number(), direction()) :: t()
  def survey_area(lat, lon, h, length, width, spacing, direction), do: survey(pos!(:survey_area, lat, lon, h), length, width, spacing, direction)

  defp survey(base, length, width, spacing, direction) do
    cmd(:survey_area,
      base: base,
      length: positive!(:survey_area, :length, length),
      width: positive!(:survey_area, :width, width),
      spacing: positive!(:survey_area, :spacing, spacing),
      direction: direction!(direction)
    )
  end

  # --- camera -----------------------------------------------------------------

  @doc """
  Takes one picture.

      capture_photo()
  """
  @spec capture_photo() :: t()
  def capture_photo, do: cmd(:capture_photo, [])

  @doc """
  Takes `count` pictures, one every `interval` seconds (default 2).

      capture_several_photos 10, 2
  """
  @spec capture_several_photos(pos_integer(), number()) :: t()
  def capture_several_photos(count, interval \\ @default_interval) do
    unless is_integer(count) and count > 0,
      do: raise(ArgumentError, "capture_several_photos: the photo count must be a positive integer, got: #{inspect(count)}")

    cmd(:capture_several_photos, count: count, interval: interval!(:capture_several_photos, interval))
  end

  @doc """
  Takes a picture every `interval` seconds (default 2) until `stop_capturing/0`.

      capture_until_stop 5
  """
  @spec capture_until_stop(number()) :: t()
  def capture_until_stop(interval \\ @default_interval), do: cmd(:capture_until_stop, interval: interval!(:capture_until_stop, interval))

  @doc """
  Stops the pictures started by `capture_until_stop/1` (or `capture_several_photos/2`).

      stop_capturing()
  """
  @spec stop_capturing() :: t()
  def stop_capturing, do: cmd(:stop_capturing, [])

  # --- flow ---------------------------------------------------------------------

  @doc """
  Jumps to mission item `item` (its sequence number in `Dolphin.Mission.to_items/1`:
  1 is the first item after home), `repeat` times (default 1; `:forever` or
  `-1` for ever).

      jump_to_item 2, :forever
  """
  @spec jump_to_item(pos_integer(), integer() | :forever) :: t()
  def jump_to_item(item, repeat \\ 1) do
    unless is_integer(item) and item >= 1,
      do: raise(ArgumentError, "jump_to_item: the target is a mission item number from 1 (0 is home), got: #{inspect(item)}")

    repeat =
      case repeat do
        :forever -> -1
        n when is_integer(n) and n >= -1 -> n
        other -> raise ArgumentError, "jump_to_item: repeat is a count, -1 or :forever, got: #{inspect(other)}"
      end

    cmd(:jump_to_item, item: item, repeat: repeat)
  end

  @doc """
  Any other MAVLink mission item, as is: `command` is a `MAV_CMD` name
  (`:mav_cmd_do_set_servo`) or number; options `params: [p1, p2, p3, p4]`
  (numbers or `:nan`, default zeros), and either `position:` (a location:
  frame MAV_FRAME_GLOBAL_INT) or `frame:` (a `MAV_FRAME` number, default
  MAV_FRAME_MISSION) with raw `x:`, `y:` (integers), `z:`; `autocontinue:`
  (default 1). Plans imported from QGroundControl (`Dolphin.Mission.from_plan/2`)
  use it for items that no other command produces.

      item :mav_cmd_do_set_servo, params: [9, 1900, 0, 0]
  """
  @spec item(atom() | non_neg_integer(), keyword()) :: t()
  def item(command, opts \\ []) do
    number =
      case command do
        n when is_integer(n) and n >= 0 and n <= 0xFFFF ->
          n

        name when is_atom(name) ->
          case Dolphin.MAVLink.Ardupilotmega.enum_value(:mav_cmd, name) do
            {:ok, n} -> n
            _ -> raise ArgumentError, "item: unknown MAV_CMD #{inspect(name)}"
          end

        other ->
          raise ArgumentError, "item: the command is a MAV_CMD name or number, got: #{inspect(other)}"
      end

    unless Keyword.keyword?(opts), do: raise(ArgumentError, "item: options must be a keyword list, got: #{inspect(opts)}")

    case Keyword.keys(opts) -- [:params, :position, :frame, :x, :y, :z, :autocontinue] do
      [] -> :ok
      unknown -> raise ArgumentError, "item: unknown options #{inspect(unknown)}"
    end

    params = Keyword.get(opts, :params, [0, 0, 0, 0])

    unless is_list(params) and length(params) == 4 and Enum.all?(params, &(is_number(&1) or &1 == :nan)),
      do: raise(ArgumentError, "item: params are four numbers (or :nan), got: #{inspect(params)}")

    {frame, x, y, z} =
      case Keyword.fetch(opts, :position) do
        {:ok, %Location{} = p} -> {5, round(p.lat * 1.0e7), round(p.lon * 1.0e7), p.h}
        {:ok, other} -> raise ArgumentError, "item: position must be a location, got: #{inspect(other)}"
        :error -> {Keyword.get(opts, :frame, 2), Keyword.get(opts, :x, 0), Keyword.get(opts, :y, 0), Keyword.get(opts, :z, 0)}
      end

    unless is_integer(frame) and frame in 0..255, do: raise(ArgumentError, "item: frame is a MAV_FRAME number, got: #{inspect(frame)}")
    unless is_integer(x) and is_integer(y), do: raise(ArgumentError, "item: x and y are integers, got: #{inspect({x, y})}")
    unless is_number(z) or z == :nan, do: raise(ArgumentError, "item: z is a number, got: #{inspect(z)}")
    autocontinue = Keyword.get(opts, :autocontinue, 1)
    unless autocontinue in [0, 1], do: raise(ArgumentError, "item: autocontinue is 0 or 1, got: #{inspect(autocontinue)}")

    cmd(:item,
      command: number,
      frame: frame,
      params: Enum.map(params, &float_or_nan/1),
      x: x,
      y: y,
      z: float_or_nan(z),
      autocontinue: autocontinue
    )
  end

  defp float_or_nan(:nan), do: :nan
  defp float_or_nan(n), do: n / 1

  # --- validation -----------------------------------------------------------

  defp cmd(kind, args), do: %__MODULE__{kind: kind, args: args}

  defp pos!(_fun, %Location{} = p), do: p
  defp pos!(fun, other), do: raise(ArgumentError, "#{fun}: expected a location (or lat, lon, h), got: #{inspect(other)}")

  defp pos!(fun, lat, lon, h) do
    Location.new(lat, lon, h)
  rescue
    e in ArgumentError -> reraise ArgumentError, "#{fun}: #{Exception.message(e)}", __STACKTRACE__
  end

  defp arity_error(fun, args),
    do: raise(ArgumentError, "#{fun}: a position is a location or lat, lon, h; got only #{Enum.map_join(args, ", ", &inspect/1)}")

  defp neu(fun, north, east, up), do: [north: num!(fun, :north, north), east: num!(fun, :east, east), up: num!(fun, :up, up)]

  defp num!(_fun, _what, n) when is_number(n), do: n
  defp num!(fun, what, other), do: raise(ArgumentError, "#{fun}: #{what} must be a number, got: #{inspect(other)}")

  defp positive!(_fun, _what, n) when is_number(n) and n > 0, do: n
  defp positive!(fun, what, other), do: raise(ArgumentError, "#{fun}: #{what} must be a positive number of metres, got: #{inspect(other)}")

  defp count!(_fun, _what, n) when is_number(n) and n >= 0, do: n
  defp count!(fun, what, other), do: raise(ArgumentError, "#{fun}: #{what} must be a non-negative number, got: #{inspect(other)}")

  defp secs!(_fun, _what, n) when is_number(n) and n >= 0, do: n
  defp secs!(fun, what, other), do: raise(ArgumentError, "#{fun}: #{what} must be a non-negative number of seconds, got: #{inspect(other)}")

  defp interval!(_fun, n) when is_number(n) and n > 0, do: n
  defp interval!(fun, other), do: raise(ArgumentError, "#{fun}: the interval must be a positive number of seconds, got: #{inspect(other)}")

  defp yaw!(_fun, :nan), do: :nan
  defp yaw!(_fun, n) when is_number(n), do: n
  defp yaw!(fun, other), do: raise(ArgumentError, "#{fun}: yaw must be a number of degrees or :nan, got: #{inspect(other)}")

  defp land_mode!(_fun, n) when n in [0, 1, 2], do: n
  defp land_mode!(_fun, name) when is_map_key(@land_modes, name), do: Map.fetch!(@land_modes, name)

  defp land_mode!(fun, other),
    do: raise(ArgumentError, "#{fun}: the land mode is 0 (:disabled), 1 (:opportunistic) or 2 (:required), got: #{inspect(other)}")

  defp speed_type!(n) when n in [0, 1, 2, 3], do: n
  defp speed_type!(name) when is_map_key(@speed_types, name), do: Map.fetch!(@speed_types, name)

  defp speed_type!(other),
    do: raise(ArgumentError, "speed: the speed type is 0 (:airspeed), 1 (:ground_speed), 2 (:climb_speed) or 3 (:descent_speed), got: #{inspect(other)}")

  defp direction!(d) when d in @directions, do: d

  defp direction!(d) when is_binary(d) do
    Enum.find(@directions, &(Atom.to_string(&1) == String.downcase(d))) || direction_error(d)
  end

  defp direction!(other), do: direction_error(other)

  defp direction_error(other),
    do: raise(ArgumentError, "survey_area: the direction is :north_west, :north_east, :south_west or :south_east, got: #{inspect(other)}")

  defimpl Inspect do
    alias Dolphin.Geo.Location

    def inspect(%{kind: kind, args: args}, _opts) do
      shown = for {k, v} <- args, {k, v} != {:base, :previous}, do: show(v)
      "#{kind}(#{Enum.join(shown, ", ")})"
    end

    defp show(%Location{lat: lat, lon: lon, h: h}), do: "location(#{Location.format(lat, 9)}, #{Location.format(lon, 9)}, #{Location.format(h, 3)})"
    defp show(v) when is_float(v), do: Location.format(v, 9)
    defp show(v), do: Kernel.inspect(v)
  end
end
