defmodule Dolphin.Mission.Plan do
  @moduledoc """
  QGroundControl plan files (`.plan`, JSON) to and from missions; used by
  `Dolphin.Mission.to_plan/2` and `Dolphin.Mission.from_plan/2`.

  The format is QGroundControl's (its developer guide, "Plan File Format"):

      {"fileType": "Plan", "version": 1, "groundStation": "Dolphin",
       "mission": {"version": 2, "firmwareType": 3, "vehicleType": 2,
                   "cruiseSpeed": 15, "hoverSpeed": 5, "globalPlanAltitudeMode": 2,
                   "plannedHomePosition": [lat, lon, alt_amsl],
                   "items": [{"type": "SimpleItem", "autoContinue": true, "command": 22,
                              "doJumpId": 1, "frame": 0,
                              "params": [15, 0, 0, null, lat, lon, alt],
                              "AltitudeMode": 2, "Altitude": alt, "AMSLAltAboveTerrain": null}, ...]},
       "geoFence": {"circles": [], "polygons": [], "version": 2},
       "rallyPoints": {"points": [], "version": 2}}

  One `SimpleItem` per mission item after home (home is
  `plannedHomePosition`); `doJumpId` is the item's seq; `params` are the
  seven MAVLink params, latitude and longitude in degrees, NaN as `null`.
  QGroundControl writes the non-`_INT` frames (0 absolute, 3 relative to home,
  10 above terrain) and marks items with a position with their
  `AltitudeMode` (2 absolute, 1 relative, 4 terrain frame); the `_INT` frames
  of our items (5, 6, 11) are written as those, and read back as the `_INT`
  frames, so a mission's items survive a round trip exactly. Items keep their
  altitude frame: a plan made relative to home stays relative to home.

  Complex items (QGroundControl's own surveys, corridor scans...) are not read:
  `{:error, %PlanError{reason: :unsupported_item}}`.
  """

  alias Dolphin.Geo.Location
  alias Dolphin.JSONText
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Mission
  alias Dolphin.Mission.{Command, Items, PlanError}

  # Our (_INT) frame -> the plan's frame, and the QGroundControl AltitudeMode of each.
  @to_plan_frame %{5 => 0, 6 => 3, 11 => 10}
  @from_plan_frame %{0 => 5, 3 => 6, 10 => 11}
  @altitude_mode %{0 => 2, 3 => 1, 10 => 4}
  @global_frames [0, 3, 5, 6, 10, 11]

  @doc "The plan as JSON text (pretty-printed)."
  @spec encode(Mission.t(), keyword()) :: binary()
  def encode(%Mission{} = mission, opts \\ []) do
    json = mission |> to_map(opts) |> ordered() |> :jiffy.encode([:pretty]) |> IO.iodata_to_binary()
    # jiffy spreads an empty array over lines.
    String.replace(json, ~r/\[\s+\]/, "[]")
  end

  # Keys in sorted order, as QGroundControl writes them (jiffy keeps the order of a proplist).
  defp ordered(%{} = map), do: {map |> Enum.sort() |> Enum.map(fn {k, v} -> {k, ordered(v)} end)}
  defp ordered(list) when is_list(list), do: Enum.map(list, &ordered/1)
  defp ordered(other), do: other

  @doc "The plan as a JSON-able map (for `:jiffy.encode/1`)."
  @spec to_map(Mission.t(), keyword()) :: map()
  def to_map(%Mission{} = mission, opts \\ []) do
    [home | items] = Mission.to_items(mission, Keyword.take(opts, [:home]))
    plan_items = Enum.map(items, &plan_item/1)

    modes = for %{"AltitudeMode" => mode} <- plan_items, uniq: true, do: mode

    %{
      "fileType" => "Plan",
      "version" => 1,
      "groundStation" => "Dolphin",
      "mission" => %{
        "version" => 2,
        "firmwareType" => 3,
        "vehicleType" => Keyword.get(opts, :vehicle_type, 2),
        "cruiseSpeed" => Keyword.get(opts, :cruise_speed, 15),
        "hoverSpeed" => Keyword.get(opts, :hover_speed, 5),
        "globalPlanAltitudeMode" =>
          case modes do
            [] -> 2
            [mode] -> mode
            _mixed -> 0
          end,
        "plannedHomePosition" => [home.x / 1.0e7, home.y / 1.0e7, home.z],
        "items" => plan_items
      },
      "geoFence" => geo_fence(mission.fence),
      "rallyPoints" => %{"points" => rally_points(mission.fence, home.z), "version" => 2}
    }
  end

  # The mission's fence as QGroundControl keeps one: its zones (the
  # altitude band and the breach action are the vehicle's parameters, not
  # the plan's), its rally points at their height above the planned home.
  defp geo_fence(nil), do: %{"circles" => [], "polygons" => [], "version" => 2}

  defp geo_fence(%Dolphin.Fence{} = fence) do
    zones = Enum.map(fence.include, &{&1, true}) ++ Enum.map(fence.exclude, &{&1, false})

    %{
      "circles" => for({%Dolphin.Geo.Circle{centre: c, radius: r}, inclusion} <- zones, do: %{"circle" => %{"center" => [c.lat, c.lon], "radius" => r}, "inclusion" => inclusion, "version" => 1}),
      "polygons" => for({%Dolphin.Geo.Polygon{points: points}, inclusion} <- zones, do: %{"inclusion" => inclusion, "polygon" => Enum.map(points, &[&1.lat, &1.lon]), "version" => 1}),
      "version" => 2
    }
  end

  defp rally_points(nil, _home_h), do: []
  defp rally_points(%Dolphin.Fence{rally: points}, home_h), do: for(p <- points, do: [p.lat, p.lon, p.h - home_h])

  defp plan_item(item) do
    frame = Map.get(@to_plan_frame, item.frame, item.frame)
    global? = item.frame in @global_frames
    {x, y} = if global?, do: {item.x / 1.0e7, item.y / 1.0e7}, else: {item.x, item.y}

    base = %{
      "type" => "SimpleItem",
      "autoContinue" => item.autocontinue == 1,
      "command" => item.command,
      "doJumpId" => item.seq,
      "frame" => frame,
      "params" => Enum.map([item.param1, item.param2, item.param3, item.param4, x, y, item.z], &json_number/1)
    }

    if global?,
      do: Map.merge(base, %{"AltitudeMode" => Map.fetch!(@altitude_mode, frame), "Altitude" => json_number(item.z), "AMSLAltAboveTerrain" => :null}),
      else: base
  end

  defp json_number(:nan), do: :null
  defp json_number(n) when is_number(n), do: n
  # An infinity or other NaN has no JSON form either.
  defp json_number(_other), do: :null

  @doc "A mission from a plan (JSON text or decoded map); see `Dolphin.Mission.from_plan/2`."
  @spec decode(binary() | map(), keyword()) :: {:ok, Mission.t()} | {:error, PlanError.t()}
  def decode(plan, opts \\ [])

  def decode(json, opts) when is_binary(json) do
    case JSONText.decode(json) do
      {:ok, value} -> decode(value, opts)
      {:error, where_and_why} -> {:error, %PlanError{reason: :invalid_json, detail: where_and_why}}
    end
  end

  def decode(%{} = plan, opts) do
    with :ok <- check(plan["fileType"] == "Plan", :not_a_plan, field("fileType", plan, ~s("Plan"))),
         :ok <- check(plan["version"] == 1, :unsupported_version, field("version", plan, "1")),
         {:ok, mission} <- object(plan, "mission"),
         :ok <- check(mission["version"] == 2, :unsupported_version, field("mission.version", mission, "version", "2")),
         {:ok, home} <- home(mission),
         {:ok, items} <- items(mission),
         {:ok, fence} <- fence(plan, home) do
      name = Keyword.get(opts, :name, "plan")
      {:ok, %{mission_from_items(name, home, items) | fence: fence}}
    end
  end

  def decode(other, _opts),
    do: {:error, %PlanError{reason: :not_a_plan, detail: "the file holds #{JSONText.kind(other)} (#{JSONText.show(other)}), not an object with \"fileType\": \"Plan\""}}

  # What a field of `object` is, against what it should be: the words of
  # the error about it.
  defp field(name, object, expected), do: field(name, object, name, expected)

  defp field(name, object, key, expected) do
    case Map.fetch(object, key) do
      {:ok, value} -> ~s|"#{name}" is #{JSONText.show(value)}, not #{expected}|
      :error -> ~s|no "#{name}" (#{expected} expected)|
    end
  end

  defp object(plan, key) do
    case Map.fetch(plan, key) do
      {:ok, %{} = object} -> {:ok, object}
      {:ok, other} -> {:error, %PlanError{reason: :not_a_plan, detail: ~s|"#{key}" is #{JSONText.kind(other)} (#{JSONText.show(other)}), not an object|}}
      :error -> {:error, %PlanError{reason: :not_a_plan, detail: ~s|no "#{key}"|}}
    end
  end

  # The plan's geoFence and rallyPoints as the mission's fence (nil when it has none).
  defp fence(plan, home) do
    geo = Map.get(plan, "geoFence", %{})
    rally = Map.get(plan, "rallyPoints", %{})

    with {:ok, zones} <- zones(geo),
         {:ok, points} <- rally(rally, home) do
      {include, exclude} = Enum.split_with(zones, &elem(&1, 1))
      opts = Enum.map(include, &{:include, elem(&1, 0)}) ++ Enum.map(exclude, &{:exclude, elem(&1, 0)}) ++ [rally: points]

      case Dolphin.Fence.new(opts) do
        {:ok, %{include: [], exclude: [], rally: []}} -> {:ok, nil}
        {:ok, fence} -> {:ok, fence}
        {:error, why} -> {:error, %PlanError{reason: :invalid_fence, detail: why}}
      end
    end
  end

  defp zones(%{} = geo) do
    polygons = for {json, i} <- Enum.with_index(List.wrap(Map.get(geo, "polygons", [])), 1), do: zone(:polygon, json, i)
    circles = for {json, i} <- Enum.with_index(List.wrap(Map.get(geo, "circles", [])), 1), do: zone(:circle, json, i)

    case Enum.find(polygons ++ circles, &match?({:error, _}, &1)) do
      nil -> {:ok, polygons ++ circles}
      error -> error
    end
  end

  defp zones(other), do: {:error, %PlanError{reason: :invalid_fence, detail: ~s|"geoFence" is #{JSONText.show(other)}, not an object|}}

  defp zone(:polygon, %{"polygon" => corners} = json, i) when is_list(corners) do
    with {:ok, points} <- corners(corners, "geoFence polygon #{i}"),
         {:ok, polygon} <- wrap(Dolphin.Geo.Shapes.polygon(points), "geoFence polygon #{i}") do
      {polygon, Map.get(json, "inclusion", true) != false}
    end
  end

  defp zone(:circle, %{"circle" => %{"center" => [lat, lon], "radius" => r}} = json, i) when is_number(lat) and is_number(lon) do
    with {:ok, circle} <- wrap(Dolphin.Geo.Shapes.circle(Location.new(lat, lon, 0), r), "geoFence circle #{i}"),
         do: {circle, Map.get(json, "inclusion", true) != false}
  end

  defp zone(kind, json, i), do: {:error, %PlanError{reason: :invalid_fence, detail: "geoFence #{kind} #{i} is #{JSONText.show(json)}"}}

  defp corners(corners, what) do
    if Enum.all?(corners, &match?([lat, lon | _] when is_number(lat) and is_number(lon) and abs(lat) <= 90 and abs(lon) <= 180, &1)),
      do: {:ok, Enum.map(corners, fn [lat, lon | _] -> Location.new(lat, lon, 0) end)},
      else: {:error, %PlanError{reason: :invalid_fence, detail: "#{what}: its corners are [latitude, longitude] pairs, got #{JSONText.show(corners)}"}}
  end

  defp wrap({:ok, value}, _what), do: {:ok, value}
  defp wrap({:error, why}, what), do: {:error, %PlanError{reason: :invalid_fence, detail: "#{what}: #{why}"}}

  # Rally points are written at their height above the planned home.
  defp rally(%{} = rally, home) do
    points = List.wrap(Map.get(rally, "points", []))

    if Enum.all?(points, &match?([lat, lon, h] when is_number(lat) and is_number(lon) and is_number(h), &1)),
      do: {:ok, for([lat, lon, h] <- points, do: Location.new(lat, lon, home.h + h))},
      else: {:error, %PlanError{reason: :invalid_fence, detail: "rallyPoints: each point is [latitude, longitude, height above home], got #{JSONText.show(points)}"}}
  end

  defp rally(other, _home), do: {:error, %PlanError{reason: :invalid_fence, detail: ~s|"rallyPoints" is #{JSONText.show(other)}, not an object|}}

  defp check(true, _reason, _detail), do: :ok
  defp check(false, reason, detail), do: {:error, %PlanError{reason: reason, detail: detail}}

  defp home(%{"plannedHomePosition" => [lat, lon, alt]}) when is_number(lat) and is_number(lon) and is_number(alt) and lat >= -90 and lat <= 90 and lon >= -180 and lon <= 180,
    do: {:ok, Location.new(lat, lon, alt)}

  defp home(mission),
    do: {:error, %PlanError{reason: :invalid_home, detail: field("plannedHomePosition", mission, "[latitude, longitude, altitude] with latitude -90..90 and longitude -180..180")}}

  defp items(%{"items" => list}) when is_list(list) do
    jump_ids = list |> Enum.with_index(1) |> Map.new(fn {item, seq} -> {is_map(item) && item["doJumpId"], seq} end)

    list
    |> Enum.with_index(1)
    |> Enum.reduce_while({:ok, []}, fn {json, seq}, {:ok, acc} ->
      case item(json, seq, jump_ids) do
        {:ok, item} -> {:cont, {:ok, [item | acc]}}
        {:error, why} -> {:halt, {:error, %PlanError{reason: :invalid_item, detail: "item #{seq}: #{why}"}}}
        {:error, reason, why} -> {:halt, {:error, %PlanError{reason: reason, detail: "item #{seq} #{why}"}}}
      end
    end)
    |> case do
      {:ok, items} -> {:ok, Enum.reverse(items)}
      error -> error
    end
  end

  defp items(mission), do: {:error, %PlanError{reason: :not_a_plan, detail: field("mission.items", mission, "items", "an array of items")}}

  @jump Items.command_number(:mav_cmd_do_jump)

  # An item of the plan, or what is wrong with it: the field, what it holds
  # and what it should.
  defp item(%{"type" => "SimpleItem"} = json, seq, jump_ids) do
    with {:ok, command} <- whole(json, "command", 0..0xFFFF, "a MAVLink command number"),
         {:ok, frame} <- whole(json, "frame", 0..255, "a MAV_FRAME number"),
         {:ok, [p1, p2, p3, p4, p5, p6, p7]} <- params(json),
         :ok <- auto_continue(json),
         frame = Map.get(@from_plan_frame, frame, frame),
         {:ok, x, y} <- xy(frame, p5, p6) do
      # DO_JUMP's param 1 names the target by doJumpId; the vehicle wants its seq.
      p1 = if command == @jump and is_float(p1), do: Map.get(jump_ids, trunc(p1), p1) / 1, else: p1

      {:ok,
       %M.MissionItemInt{
         seq: seq,
         command: command,
         frame: frame,
         param1: p1,
         param2: p2,
         param3: p3,
         param4: p4,
         x: x,
         y: y,
         z: p7,
         autocontinue: if(Map.get(json, "autoContinue", true) == false, do: 0, else: 1),
         current: 0,
         mission_type: 0
       }}
    end
  end

  defp item(%{"type" => type}, _seq, _) when is_binary(type),
    do: {:error, :unsupported_item, "is a #{inspect(type)}; only SimpleItem items are read (save the plan with its complex items converted to waypoints)"}

  defp item(%{} = json, _seq, _), do: {:error, field("type", json, ~s("SimpleItem"))}
  defp item(other, _seq, _), do: {:error, "it is #{JSONText.kind(other)} (#{JSONText.show(other)}), not an object"}

  defp whole(json, key, first..last = range, what) do
    case Map.fetch(json, key) do
      {:ok, n} when is_integer(n) -> if n in range, do: {:ok, n}, else: {:error, field(key, json, "#{what} (#{first}..#{last})")}
      _ -> {:error, field(key, json, "#{what} (#{first}..#{last})")}
    end
  end

  defp params(%{"params" => params}) when is_list(params) and length(params) == 7 do
    case Enum.find_index(params, &(not (is_number(&1) or &1 == :null))) do
      nil ->
        {:ok,
         Enum.map(params, fn
           :null -> :nan
           n -> n / 1
         end)}

      i ->
        {:error, ~s|"params" #{i + 1} is #{JSONText.show(Enum.at(params, i))}, not a number or null|}
    end
  end

  defp params(json), do: {:error, field("params", json, "7 numbers or nulls")}

  defp auto_continue(json) do
    case Map.fetch(json, "autoContinue") do
      {:ok, flag} when not is_boolean(flag) -> {:error, field("autoContinue", json, "true or false")}
      _ -> :ok
    end
  end

  defp xy(frame, lat, lon) when frame in @global_frames do
    cond do
      not (is_float(lat) and lat >= -90 and lat <= 90) -> {:error, ~s|"params" 5, the latitude, is #{number(lat)}, not within -90..90|}
      not (is_float(lon) and lon >= -180 and lon <= 180) -> {:error, ~s|"params" 6, the longitude, is #{number(lon)}, not within -180..180|}
      true -> {:ok, round(lat * 1.0e7), round(lon * 1.0e7)}
    end
  end

  # MAVLink's x and y are int32 in the frames without a position.
  defp xy(frame, x, y) do
    if is_float(x) and is_float(y) and x == trunc(x) and y == trunc(y) and abs(x) < 2_147_483_648 and abs(y) < 2_147_483_648,
      do: {:ok, trunc(x), trunc(y)},
      else: {:error, ~s|"params" 5 and 6 are #{number(x)} and #{number(y)}: in frame #{frame} they are whole numbers (x and y)|}
  end

  defp number(:nan), do: "null"
  defp number(x), do: JSONText.show(x)

  # Each item becomes the command that gives it back exactly; an item no
  # command reproduces (checked by generating the items) stays a raw `item`.
  defp mission_from_items(name, home, items) do
    commands = Enum.map(items, &guess/1)
    settle(Mission.new(name) |> Mission.put_home(home), commands, items)
  end

  defp settle(base, commands, items) do
    generated = base |> Mission.add(commands) |> Mission.to_items() |> tl()

    wrong = for {{made, wanted}, i} <- Enum.with_index(Enum.zip(generated, items)), not same?(made, wanted), into: MapSet.new(), do: i

    if MapSet.size(wrong) == 0 and length(generated) == length(items) do
      Mission.add(base, commands)
    else
      commands = for {{command, item}, i} <- Enum.with_index(Enum.zip(commands, items)), do: if(i in wrong, do: raw(item), else: command)
      settle(base, commands, items)
    end
  end

  defp same?(a, b) do
    Map.take(a, [:command, :frame, :param1, :param2, :param3, :param4, :x, :y, :z, :autocontinue]) ==
      Map.take(b, [:command, :frame, :param1, :param2, :param3, :param4, :x, :y, :z, :autocontinue])
  end

  defp raw(item) do
    Command.item(item.command,
      params: [item.param1, item.param2, item.param3, item.param4],
      frame: item.frame,
      x: item.x,
      y: item.y,
      z: item.z,
      autocontinue: item.autocontinue
    )
  end

  @waypoint Items.command_number(:mav_cmd_nav_waypoint)
  @takeoff Items.command_number(:mav_cmd_nav_takeoff)
  @unlim Items.command_number(:mav_cmd_nav_loiter_unlim)
  @turns Items.command_number(:mav_cmd_nav_loiter_turns)
  @time Items.command_number(:mav_cmd_nav_loiter_time)
  @land Items.command_number(:mav_cmd_nav_land)
  @speed Items.command_number(:mav_cmd_do_change_speed)
  @delay Items.command_number(:mav_cmd_nav_delay)
  @start_capture Items.command_number(:mav_cmd_image_start_capture)
  @stop_capture Items.command_number(:mav_cmd_image_stop_capture)

  defp guess(%{frame: 5, z: z} = i) when is_float(z) do
    p = Location.new(i.x / 1.0e7, i.y / 1.0e7, z)

    case {i.command, i.param1, i.param2, i.param3, i.param4} do
      {@waypoint, _, _, _, _} -> Command.go_pos(p)
      {@takeoff, pitch, _, _, :nan} when is_float(pitch) -> Command.take_off(p, pitch)
      {@takeoff, pitch, _, _, yaw} when is_float(pitch) -> Command.take_off_with_yaw(p, pitch, yaw)
      {@unlim, _, _, radius, _} when is_float(radius) -> Command.loiter_pos(p, radius)
      {@turns, turns, _, radius, _} when is_float(turns) and turns >= 0 and is_float(radius) -> Command.loiter_turns(p, turns, radius)
      {@time, time, _, radius, _} when is_float(time) and time >= 0 and is_float(radius) -> Command.loiter_time(p, time, radius)
      {@land, _, mode, _, yaw} when mode in [0.0, 1.0, 2.0] -> Command.landing_point(p, yaw, trunc(mode))
      _ -> raw(i)
    end
  end

  defp guess(%{frame: 2} = i) do
    case {i.command, i.param1, i.param2, i.param3} do
      {@speed, type, speed, _} when type in [0.0, 1.0, 2.0, 3.0] and is_float(speed) ->
        Command.speed(speed, trunc(type))

      {@delay, seconds, _, _} when is_float(seconds) and seconds >= 0 ->
        Command.delay(seconds)

      {@start_capture, _, _, 1.0} ->
        Command.capture_photo()

      {@start_capture, _, interval, 0.0} when is_float(interval) and interval > 0 ->
        Command.capture_until_stop(interval)

      {@start_capture, _, interval, n} when is_float(interval) and interval > 0 and is_float(n) and n > 1 and n == trunc(n) ->
        Command.capture_several_photos(trunc(n), interval)

      {@stop_capture, _, _, _} ->
        Command.stop_capturing()

      {@jump, item, repeat, _} when is_float(item) and item >= 1 and item == trunc(item) and is_float(repeat) and repeat >= -1 and repeat == trunc(repeat) ->
        Command.jump_to_item(trunc(item), trunc(repeat))

      _ ->
        raw(i)
    end
  end

  defp guess(i), do: raw(i)
end
