defmodule Dolphin.Mission do
  @moduledoc """
  A MAVLink mission as plain data: a name, a home position and the commands
  of the report's Table 2 (`Dolphin.Mission.Command`), in order. Nothing flies
  here: `to_items/1` gives the exact `MISSION_ITEM_INT` list a vehicle is sent,
  `to_plan/1` and `from_plan/1` read and write QGroundControl plan files, and
  a mission can be inspected, stored and reused — with another home, even.

  Built by the `mission "name" do ... end` block of scripts
  (`Dolphin.DSL.Mission`) or by functions:

      iex> alias Dolphin.Mission
      iex> alias Dolphin.Mission.Command, as: C
      iex> home = Dolphin.Geo.location(40.444233, -7.375234, 820)
      iex> m =
      ...>   Mission.new("Survey Area")
      ...>   |> Mission.add(C.home(home))
      ...>   |> Mission.add(C.take_off(40.444233, -7.375234, 1200))
      ...>   |> Mission.add([C.move(100, 200, 100), C.move_and_loiter_pos(200, 100, -20, 50)])
      iex> [home_item, take_off, _move, loiter] = Mission.to_items(m)
      iex> {home_item.seq, home_item.command, home_item.z}
      {0, 16, 820.0}
      iex> {take_off.seq, take_off.command, take_off.frame, take_off.x, take_off.y, take_off.z, take_off.param1}
      {1, 22, 5, 404442330, -73752340, 1200.0, 15.0}
      iex> {loiter.command, loiter.param3, loiter.z}
      {17, 50.0, 1280.0}

  ## From the report's Table 2 to MAVLink

  Every item has `autocontinue` 1, `current` 0 and `mission_type` 0 (the
  mission list); seq runs from 0. Positions use frame `MAV_FRAME_GLOBAL_INT`
  (5): latitude and longitude in degrees × 10⁷, `z` in metres above mean sea
  level — the report's heights, never relative to home. (Recent `common.xml`
  marks frame 5 as superseded by `MAV_FRAME_GLOBAL` (0), its synonym; ArduPilot
  takes both and reports 0 on download.) Items without a position use
  `MAV_FRAME_MISSION` (2) with x = y = 0 and z = 0. Each command is one item
  except `survey_area` (two per pass); commands that are not navigation
  (speed, camera, jump) keep their place in the sequence, where ArduPilot runs
  them on its way to the next navigation item.

  | Table 2 (Groovy) | here | item: MAV_CMD (number) | params 1–4 |
  |---|---|---|---|
  | `name(String)` | `name "x"` (or `mission "x" do`) | — | — |
  | `home(lat, lon, hae)`, `home(Position)` | `home loc` | item 0: NAV_WAYPOINT (16) at home | 0, 0, 0, 0 |
  | `goPos(lat, lon, hae)` | `go_pos loc` | NAV_WAYPOINT (16) | hold 0, 0, 0, yaw NaN |
  | `takeOff(Position p, pitch = 15)` | `take_off loc, pitch \\\\ 15` | NAV_TAKEOFF (22) at `p` | pitch, 0, 0, yaw NaN |
  | `takeOffWithYaw(p, pitch, yaw = NaN)` | `take_off_with_yaw loc, pitch, yaw \\\\ :nan` | NAV_TAKEOFF (22) | pitch, 0, 0, yaw |
  | `move(north, east, up)` | `move n, e, up` | NAV_WAYPOINT, previous point + offset | 0, 0, 0, NaN |
  | `moveFromHome(north, east, up)` | `move_from_home n, e, up` | NAV_WAYPOINT, home + offset | 0, 0, 0, NaN |
  | `moveAndLoiterPos(n, e, up, radius = 15)` | `move_and_loiter_pos n, e, up, r \\\\ 15` | NAV_LOITER_UNLIM (17) | 0, 0, radius, 0 |
  | `moveAndLoiterTurns(n, e, up, turns, radius = 15)` | `move_and_loiter_turns n, e, up, turns, r \\\\ 15` | NAV_LOITER_TURNS (18) | turns, 0, radius, 0 |
  | `moveAndLoiterTime(n, e, up, time, radius = 15)` | `move_and_loiter_time n, e, up, s, r \\\\ 15` | NAV_LOITER_TIME (19) | seconds, 0, radius, 0 |
  | `moveAndLoiter[Turns\\|Time]FromHome(...)` | `move_and_loiter[_turns\\|_time]_from_home ...` | as above, from home | as above |
  | `loiterPos(pos, radius = 15)` | `loiter_pos loc, r \\\\ 15` | NAV_LOITER_UNLIM (17) | 0, 0, radius, 0 |
  | `loiterTurns(lat, lon, h, turns, radius = 15)` | `loiter_turns loc, turns, r \\\\ 15` | NAV_LOITER_TURNS (18) | turns, 0, radius, 0 |
  | `loiterTime(lat, lon, h, time, radius = 15)` | `loiter_time loc, s, r \\\\ 15` | NAV_LOITER_TIME (19) | seconds, 0, radius, 0 |
  | `landingPoint(lat, lon, h, yaw = NaN, landMode = 0)` | `landing_point loc, yaw \\\\ :nan, mode \\\\ 0` | NAV_LAND (21) | 0, land mode, 0, yaw |
  | `returnHome()` | `return_home()` | NAV_WAYPOINT over home, previous height | 0, 0, 0, NaN |
  | `returnHomeAndLoiter(radius = 15)` | `return_home_and_loiter r \\\\ 15` | NAV_LOITER_UNLIM over home, previous height | 0, 0, radius, 0 |
  | `returnHomeAndLand(yaw = NaN, landMode = 0)` | `return_home_and_land yaw \\\\ :nan, mode \\\\ 0` | NAV_LAND (21) at home | 0, land mode, 0, yaw |
  | `speed(newSpeed, speedType = 0)` | `speed m_s, type \\\\ 0` | DO_CHANGE_SPEED (178) | type, speed, −1 (throttle unchanged), 0 |
  | `altitude(newAltitude)` | `altitude h` | NAV_WAYPOINT over the previous point at `h` | 0, 0, 0, NaN |
  | `delay(seconds)` | `delay s` | NAV_DELAY (93) | seconds, −1, −1, −1 |
  | `surveyArea(length, width, spacing = 50, dir = NORTH_WEST)` | `survey_area l, w, s \\\\ 50, dir \\\\ :north_west` | 2 NAV_WAYPOINTs per pass (`Dolphin.Mission.Survey`) | 0, 0, 0, NaN |
  | `surveyArea(Position p, length, width, ...)` | `survey_area loc, l, w, ...` | same, from `p` | same |
  | `capturePhoto()` | `capture_photo()` | IMAGE_START_CAPTURE (2000) | camera 0 (all), interval 0, 1 image, capture number 1, 2, ... |
  | `captureSeveralPhotos(count, interval = 2)` | `capture_several_photos n, s \\\\ 2` | IMAGE_START_CAPTURE (2000) | 0, interval, count, 0 |
  | `captureUntilStop(interval = 2)` | `capture_until_stop s \\\\ 2` | IMAGE_START_CAPTURE (2000) | 0, interval, 0 (until stopped), 0 |
  | `stopCapturing()` | `stop_capturing()` | IMAGE_STOP_CAPTURE (2001) | 0, 0, 0, 0 |
  | `jumpToItem(item, repetitions = 1)` | `jump_to_item seq, repeat \\\\ 1` | DO_JUMP (177) | seq, repeat (−1 for ever), 0, 0 |
  | — | `item cmd, params: [...], position: loc` | any other MAV_CMD, as given | as given |

  Why these items, for ArduCopter (4.5 and later):

    * Relative moves are azimuthal equidistant offsets on WGS84
      (`Dolphin.Geo.offset/4`) from the previous point (the last position of
      the mission so far: home at first, then each waypoint, loiter,
      take-off, landing, the end of a survey) or from home.
    * `return_home` and `return_home_and_loiter` fly over home at the height
      of the previous point: NAV_RETURN_TO_LAUNCH would land on a Copter
      (RTL_ALT_FINAL 0), which is `return_home_and_land`'s job.
      `return_home_and_land` is a NAV_LAND at home, as in the original plugin.
    * `altitude` is a waypoint straight above (or below) the previous point:
      ArduPilot does not take DO_CHANGE_ALTITUDE (the original's choice) in a
      mission, and Copter does not fly NAV_CONTINUE_AND_CHANGE_ALT.
    * The camera commands are the MAVLink camera protocol's
      IMAGE_START_CAPTURE / IMAGE_STOP_CAPTURE, which ArduPilot runs as mission
      items since 4.5 (DO_DIGICAM_CONTROL only takes single pictures).
    * NaN appears only where ArduPilot accepts it (param 4 of WAYPOINT,
      TAKEOFF and LAND); elsewhere reserved or unused params are 0.
    * Copter hovers on LOITER_UNLIM and LOITER_TIME (the radius matters to
      fixed wing only) and circles on LOITER_TURNS; ArduPilot keeps at most
      255 whole turns, radii above 255 m in steps of 10 m, and loiter times
      in whole seconds up to 65535.
    * Every Table 2 command is a mission item: nothing has to be sent to the
      vehicle while it flies (the original plugin sent its camera and some
      other commands when items were reached).

  Durations in the commands are seconds, as in the report: `delay 30`. The
  script language's duration values are milliseconds (`seconds(30)` is
  30000); `Dolphin.DSL.Mission` refuses them where seconds are expected.

  A mission without `home` takes the first absolute position among its
  commands, like the original plugin; `to_items(mission, home: location)`
  supplies or overrides it.
  """

  alias Dolphin.Airframe
  alias Dolphin.Geo.Location
  alias Dolphin.Mission.{Command, Items, Plan}

  defstruct name: "mission", home: nil, commands: [], fence: nil

  @typedoc "A mission: its name, home, commands, and its own fence (`Dolphin.Fence`; nil: the script's)."
  @type t :: %__MODULE__{name: String.t(), home: Location.t() | nil, commands: [Command.t()], fence: Dolphin.Fence.t() | nil}

  @typedoc "What `new/2` and `add/2` take: commands, lists of them (nested), `nil`s (skipped), or missions (their commands)."
  @type commands :: Command.t() | t() | nil | [commands()]

  @doc """
  A mission named `name` with `commands`. `name` and `home` commands set the
  mission's name and home rather than adding to its commands.
  """
  @spec new(String.t(), commands()) :: t()
  def new(name \\ "mission", commands \\ [])

  def new(name, commands) when is_binary(name), do: add(%__MODULE__{name: name}, commands)
  def new(name, _commands), do: raise(ArgumentError, "a mission's name is a string, got: #{inspect(name)}")

  @doc """
  Appends commands (see `t:commands/0`). Another mission's commands are
  appended as they are written: its relative moves start from this mission's
  previous point. Setting the home twice is a mistake (`put_home/2` replaces it).
  """
  @spec add(t(), commands()) :: t()
  def add(%__MODULE__{} = mission, commands), do: do_add(mission, commands)

  defp do_add(mission, nil), do: mission
  defp do_add(mission, list) when is_list(list), do: Enum.reduce(list, mission, &do_add(&2, &1))
  defp do_add(mission, %__MODULE__{commands: commands, fence: fence}), do: %{mission | commands: mission.commands ++ commands, fence: mission.fence || fence}
  defp do_add(mission, %Command{kind: :name, args: [name: name]}), do: %{mission | name: name}
  defp do_add(%__MODULE__{fence: nil} = mission, %Dolphin.Fence{} = fence), do: %{mission | fence: fence}
  defp do_add(mission, %Dolphin.Fence{}), do: raise(ArgumentError, "mission #{inspect(mission.name)} already has a fence; a mission has one (its zones are all in it)")

  defp do_add(%__MODULE__{home: nil} = mission, %Command{kind: :home, args: [position: p]}), do: %{mission | home: p}

  defp do_add(mission, %Command{kind: :home} = command),
    do: raise(ArgumentError, "mission #{inspect(mission.name)} already has a home (#{inspect(mission.home)}); got another: #{inspect(command)}")

  defp do_add(mission, %Command{} = command), do: %{mission | commands: mission.commands ++ [command]}

  defp do_add(mission, other),
    do: raise(ArgumentError, "mission #{inspect(mission.name)}: not a mission command: #{inspect(other)}")

  @doc "Sets or replaces the home position."
  @spec put_home(t(), Location.t()) :: t()
  def put_home(%__MODULE__{} = mission, %Location{} = home), do: %{mission | home: home}
  def put_home(%__MODULE__{}, other), do: raise(ArgumentError, "a home is a location, got: #{inspect(other)}")

  @doc "Renames the mission."
  @spec put_name(t(), String.t()) :: t()
  def put_name(%__MODULE__{} = mission, name) when is_binary(name), do: %{mission | name: name}
  def put_name(%__MODULE__{}, other), do: raise(ArgumentError, "a mission's name is a string, got: #{inspect(other)}")

  @doc """
  The `MISSION_ITEM_INT` structs (`Dolphin.MAVLink.Ardupilotmega.MissionItemInt`)
  to upload, seq 0 (home) first. See the module doc for what each command
  becomes. Option `home:` supplies (or overrides) the home position;
  `airframe:` (`Dolphin.Vehicles.View.airframes/0`; default a copter's items)
  the vehicle's, for what differs: a plane's landing (`landing_point`,
  `return_home_and_land`) is its landing sequence, three items —
  DO_LAND_START and a waypoint on the approach, 400 m out in line with the
  way it comes from the point before and 28 m above the landing (a 4°
  glide), then NAV_LAND; a submarine's heights are depths below its home at
  the surface, in frame GLOBAL_RELATIVE_ALT_INT (6).

      iex> alias Dolphin.Mission.Command, as: C
      iex> home = Dolphin.Geo.location(40.444233, -7.375234, 0)
      iex> dive = Dolphin.Mission.new("dive", [C.home(home), C.move(50, 0, -5), C.return_home_and_land()])
      iex> for i <- Dolphin.Mission.to_items(dive, airframe: :sub), do: {i.command, i.frame, i.z}
      [{16, 5, 0.0}, {16, 6, -5.0}, {21, 6, 0.0}]
      iex> glide = Dolphin.Mission.new("glide", [C.home(home), C.take_off(Dolphin.Geo.location(40.444233, -7.375234, 60)), C.move(0, 1000, 0), C.return_home_and_land()])
      iex> [_, _, _, start, approach, land] = Dolphin.Mission.to_items(glide, airframe: :plane)
      iex> {start.command, approach.command, land.command}
      {189, 16, 21}
      iex> {n, e} = Dolphin.Geo.ne_offset(home, Dolphin.Geo.location(approach.x / 1.0e7, approach.y / 1.0e7))
      iex> {round(n), round(e), round(approach.z)}
      {0, 400, 28}

  Raises `ArgumentError` when the mission has no home and no absolute position
  to take it from, when a jump targets an item that does not exist, or when a
  submarine's item is above the surface.
  """
  @spec to_items(t(), keyword()) :: [struct()]
  def to_items(mission, opts \\ [])

  def to_items(%__MODULE__{} = mission, opts) do
    mission = if home = Keyword.get(opts, :home), do: put_home(mission, home), else: mission
    Items.to_items(mission, Keyword.get(opts, :airframe))
  end

  @doc "The number of items `to_items/1` gives, home included."
  @spec item_count(t()) :: pos_integer()
  def item_count(%__MODULE__{} = mission), do: length(to_items(mission))

  # What each airframe can fly, by command: take-offs are for what takes
  # off; landings for what lands (ArduSub's NAV_LAND surfaces), as
  # Dolphin.Airframe says; everything else every airframe flies in its own
  # way (see docs/missions.md). A raw `item` is the script's own business.
  @take_offs [:take_off, :take_off_with_yaw]
  @landings [:landing_point, :return_home_and_land]

  @doc """
  The airframes (`Dolphin.Vehicles.View.airframes/0`) that can fly every
  command of `mission`, or `nil` for a mission of raw items only (`item`),
  which any vehicle may be given, one of unknown airframe too. A take-off
  needs a vehicle that flies (a copter, plane or quadplane); a landing one
  that flies or a submarine (which surfaces).

      iex> alias Dolphin.Mission.Command, as: C
      iex> Dolphin.Mission.airframes(Dolphin.Mission.new("go", [C.move(10, 0, 0), C.speed(3)]))
      [:copter, :plane, :quadplane, :rover, :boat, :sub]
      iex> Dolphin.Mission.airframes(Dolphin.Mission.new("up", [C.take_off(41.0, -8.0, 120), C.move(10, 0, 0)]))
      [:copter, :plane, :quadplane]
      iex> Dolphin.Mission.airframes(Dolphin.Mission.new("raw", [C.item(183, params: [9, 1900, 0, 0])]))
      nil
  """
  @spec airframes(t()) :: [Dolphin.Vehicles.View.airframe()] | nil
  def airframes(%__MODULE__{commands: commands}) do
    kinds = for %Command{kind: kind} <- commands, kind != :item, do: kind

    cond do
      commands != [] and kinds == [] -> nil
      Enum.any?(kinds, &(&1 in @take_offs)) -> Airframe.takes_off()
      Enum.any?(kinds, &(&1 in @landings)) -> Airframe.lands()
      true -> Dolphin.Vehicles.View.airframes()
    end
  end

  @doc """
  The commands of `mission` that an `airframe` cannot fly (`airframes/1`),
  as `{index in the mission's commands, kind}`: what the pre-flight check and
  an allocation refusal name.

      iex> alias Dolphin.Mission.Command, as: C
      iex> Dolphin.Mission.unflyable(Dolphin.Mission.new("up", [C.take_off(41.0, -8.0, 120), C.move(10, 0, 0), C.return_home_and_land()]), :boat)
      [{0, :take_off}, {2, :return_home_and_land}]
      iex> Dolphin.Mission.unflyable(Dolphin.Mission.new("dive", [C.move(10, 0, -5), C.return_home_and_land()]), :sub)
      []
  """
  @spec unflyable(t(), Dolphin.Vehicles.View.airframe() | nil) :: [{non_neg_integer(), atom()}]
  def unflyable(%__MODULE__{commands: commands}, airframe) do
    for {%Command{kind: kind}, i} <- Enum.with_index(commands), kind != :item, not flies?(kind, airframe), do: {i, kind}
  end

  defp flies?(_kind, nil), do: false
  defp flies?(kind, airframe) when kind in @take_offs, do: Airframe.of(airframe).takes_off?()
  defp flies?(kind, airframe) when kind in @landings, do: Airframe.of(airframe).lands?()
  defp flies?(_kind, _airframe), do: true

  @typedoc "How a mission ends (see `ending/1`)."
  @type ending ::
          {:landing, non_neg_integer()} | {:loiter_forever, non_neg_integer()} | {:loops_forever, non_neg_integer()} | {:reached, non_neg_integer()}

  @doc """
  How a mission (or a list of its items) ends, with the seq of the item that
  decides it:

    * `{:loops_forever, seq}` — a DO_JUMP repeating for ever (`seq` is the jump);
    * `{:landing, seq}` — its last navigation item lands (NAV_LAND, or
      NAV_RETURN_TO_LAUNCH, which lands on a Copter): done when landed and
      disarmed;
    * `{:loiter_forever, seq}` — its last navigation item is NAV_LOITER_UNLIM:
      it never completes by itself;
    * `{:reached, seq}` — done when navigation item `seq` is reached (0 when
      there is none).

  Navigation items (NAV_*, MAV_CMD up to 95 as ArduPilot counts them) are the
  ones a mission waits for; ArduPilot ends a mission when no navigation item
  is left, so the commands after the last one (speed, camera) are not waited
  for, and may not all run.

      iex> alias Dolphin.Mission.Command, as: C
      iex> home = Dolphin.Geo.location(40.444233, -7.375234, 820)
      iex> Dolphin.Mission.ending(Dolphin.Mission.new("r", [C.home(home), C.return_home_and_land()]))
      {:landing, 1}
      iex> Dolphin.Mission.ending(Dolphin.Mission.new("s", [C.home(home), C.move_and_loiter_pos(1, 1, 50), C.capture_photo()]))
      {:loiter_forever, 1}
  """
  @spec ending(t() | [struct()], atom() | nil) :: ending()
  def ending(mission_or_items, airframe \\ nil)
  def ending(%__MODULE__{} = mission, airframe), do: mission |> to_items(airframe: airframe) |> ending(airframe)

  # ArduSub's NAV_LAND surfaces, is reported reached, and the sub stays armed
  # at the surface: a waypoint's end, not a landing's (Dolphin.Airframe's
  # landing_done/0).
  def ending(items, airframe) when is_list(items) do
    case {landing_ending(items), Airframe.of(airframe).landing_done()} do
      {{:landing, seq}, :reached} -> {:reached, seq}
      {ending, _} -> ending
    end
  end

  defp landing_ending(items) do
    jump = Items.command_number(:mav_cmd_do_jump)

    forever = Enum.find(items, &(&1.command == jump and &1.param2 == -1.0))
    last_nav = items |> Enum.filter(&(&1.seq > 0 and &1.command <= 95)) |> List.last()

    cond do
      forever -> {:loops_forever, forever.seq}
      last_nav == nil -> {:reached, 0}
      last_nav.command in [Items.command_number(:mav_cmd_nav_land), 20] -> {:landing, last_nav.seq}
      last_nav.command == Items.command_number(:mav_cmd_nav_loiter_unlim) -> {:loiter_forever, last_nav.seq}
      true -> {:reached, last_nav.seq}
    end
  end

  @doc """
  Compares a mission downloaded from a vehicle with the items uploaded, by
  meaning: `:ok`, or `{:error, %Dolphin.Mission.MismatchError{}}` naming the
  first difference.

  What ArduPilot gives back differs from what it was sent in ways that do not
  change the mission, and those are ignored: item 0 is the vehicle's own home;
  frames come back as their non-`_INT` synonyms (5 as 0, 6 as 3, 11 as 10) and
  items without a position in any frame; heights are stored in centimetres;
  and many params are stored in narrower forms or dropped (WAYPOINT, TAKEOFF
  and LAND yaw, the LOITER_TIME radius, integer seconds and turns), so params
  are not compared. What is compared: the number of items, each item's
  command, and for items with a position its latitude and longitude (exactly,
  degrees × 10⁷), its altitude reference and its height (within 1 cm).
  """
  @spec compare_download([struct()], [struct()]) :: :ok | {:error, Dolphin.Mission.MismatchError.t()}
  def compare_download(uploaded, downloaded) when is_list(uploaded) and is_list(downloaded) do
    if length(uploaded) != length(downloaded) do
      {:error, %Dolphin.Mission.MismatchError{what: :count, on_vehicle: length(downloaded), uploaded: length(uploaded)}}
    else
      uploaded
      |> Enum.zip(downloaded)
      |> Enum.drop(1)
      |> Enum.find_value(:ok, fn {up, down} -> item_difference(up, down) end)
    end
  end

  @altitude_reference %{0 => :amsl, 5 => :amsl, 3 => :home, 6 => :home, 10 => :terrain, 11 => :terrain}

  defp item_difference(up, down) do
    reference = Map.get(@altitude_reference, up.frame)
    differs = &{:error, %Dolphin.Mission.MismatchError{what: &1, item: up.seq, on_vehicle: &2, uploaded: &3}}

    cond do
      up.command != down.command ->
        differs.(:command, down.command, up.command)

      reference == nil ->
        nil

      Map.get(@altitude_reference, down.frame) != reference ->
        differs.(:frame, down.frame, up.frame)

      {up.x, up.y} != {down.x, down.y} ->
        differs.(:position, {down.x, down.y}, {up.x, up.y})

      not (is_number(down.z) and abs(down.z - up.z) <= 0.01) ->
        differs.(:height, down.z, up.z)

      true ->
        nil
    end
  end

  @doc """
  The mission as a QGroundControl plan file (JSON text, see
  `Dolphin.Mission.Plan`). Options: `:cruise_speed` (default 15 m/s),
  `:hover_speed` (5 m/s), `:vehicle_type` (`MAV_TYPE`, 2 quadrotor),
  `:home` as for `to_items/2`.
  """
  @spec to_plan(t(), keyword()) :: binary()
  def to_plan(%__MODULE__{} = mission, opts \\ []), do: Plan.encode(mission, opts)

  @doc """
  A mission from a QGroundControl plan (JSON text, or the decoded map): its
  items become the commands that give them back exactly (`go_pos`,
  `take_off`, `loiter_*`, `landing_point`, `speed`, `delay`, the camera
  commands, `jump_to_item`, else `item`), its planned home the home. Option
  `:name` (default `"plan"`).
  """
  @spec from_plan(binary() | map(), keyword()) :: {:ok, t()} | {:error, Dolphin.Mission.PlanError.t()}
  def from_plan(plan, opts \\ []), do: Plan.decode(plan, opts)

  @doc "Like `from_plan/2`, raising `Dolphin.Mission.PlanError`."
  @spec from_plan!(binary() | map(), keyword()) :: t()
  def from_plan!(plan, opts \\ []) do
    case from_plan(plan, opts) do
      {:ok, mission} -> mission
      {:error, error} -> raise error
    end
  end

  @doc """
  How an item is named in listings: `"home"` for item 0, else its MAV_CMD
  without the prefix (`"NAV_TAKEOFF"`), or its number when the dialect does
  not know it.
  """
  @spec item_name(struct()) :: String.t()
  def item_name(%{seq: 0}), do: "home"

  def item_name(%{command: command}) do
    case Dolphin.MAVLink.Ardupilotmega.enum_name(:mav_cmd, command) do
      {:ok, atom} -> atom |> Atom.to_string() |> String.replace_prefix("mav_cmd_", "") |> String.upcase()
      _ -> "MAV_CMD #{command}"
    end
  end

  defimpl Inspect do
    def inspect(%{name: name} = mission, opts) do
      try do
        Dolphin.Mission.to_items(mission)
      rescue
        e in ArgumentError -> {:error, e}
      else
        items ->
          lines = Enum.map(items, &item_line/1)
          "#Dolphin.Mission<#{Kernel.inspect(name)}, #{length(items)} items:\n" <> Enum.join(lines, "\n") <> "\n>"
      end
      |> case do
        {:error, e} ->
          commands = Enum.map_join(mission.commands, ", ", &Inspect.inspect(&1, opts))
          "#Dolphin.Mission<#{Kernel.inspect(name)}, #{Exception.message(e)}; commands: [#{commands}]>"

        text ->
          text
      end
    end

    defp item_line(item) do
      name = Dolphin.Mission.item_name(item)

      where =
        cond do
          item.frame == 2 -> ""
          item.frame == 5 -> "#{fmt_deg(item.x)}, #{fmt_deg(item.y)}, #{fmt(item.z)} m  "
          true -> "x #{item.x}, y #{item.y}, z #{fmt(item.z)}, frame #{item.frame}  "
        end

      params = Enum.map_join([item.param1, item.param2, item.param3, item.param4], ", ", &fmt/1)
      String.pad_leading(Integer.to_string(item.seq), 4) <> " " <> String.pad_trailing(name, 20) <> " " <> where <> "[" <> params <> "]"
    end

    defp fmt_deg(e7), do: :erlang.float_to_binary(e7 / 1.0e7, decimals: 7)

    defp fmt(:nan), do: "NaN"
    defp fmt(f) when is_float(f) and f == trunc(f) and abs(f) < 1.0e15, do: Integer.to_string(trunc(f))
    defp fmt(f) when is_float(f), do: Dolphin.Geo.Location.format(f, 6)
    defp fmt(other), do: Kernel.inspect(other)
  end
end
