defmodule Dolphin.Sim.Copter.Mission do
  @moduledoc false
  # The simulated copter in AUTO: which item is current, what flying it means
  # (a navigation target, a climb, a landing, a jump, a DO command done at
  # once), when it is reached, and how ArduCopter reports the progress
  # (MISSION_CURRENT, MISSION_ITEM_REACHED, "Mission: 2 WP").

  import Dolphin.Sim.Copter, only: [say: 2, text: 3, in_air?: 1, target_alt: 3, set_home: 2, position: 1, ne: 3, distance_to: 3, surface: 1, home_ne: 1]

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.{Copter, MissionServer, Streams}
  alias Dolphin.Sim.Copter.{Camera, Flight, Plane}

  # Mission item names as ArduPilot announces them ("Mission: 2 WP").
  @item_names %{
    16 => "WP",
    17 => "LoitUnlim",
    18 => "LoitTurns",
    19 => "LoitTime",
    20 => "RTL",
    21 => "Land",
    22 => "Takeoff",
    93 => "Delay",
    112 => "CondDelay",
    113 => "CondChangeAlt",
    114 => "CondDist",
    115 => "CondYaw",
    177 => "Jump",
    178 => "ChangeSpeed",
    179 => "SetHome",
    186 => "ChangeAlt",
    189 => "LandStart",
    203 => "DigiCamCtrl",
    206 => "SetCamTrigDst",
    2000 => "ImageStartCapture",
    2001 => "ImageStopCapture"
  }

  # Items that complete at once (DO commands, jumps) are run in a row; a loop
  # of nothing else is cut, as ArduPilot bounds its search for the next command.
  @max_items_at_once 64
  # The least a take-off from the ground climbs (metres).
  @least_take_off 1.0

  # ArduCopter sends MISSION_CURRENT and MISSION_ITEM_REACHED as deferred
  # messages holding only the latest value: items that end in one loop (a
  # take-off and the DO commands flown along with it) are reported once, by
  # the last of them (docs/ardupilot.md).
  @spec latest_reports(Copter.t(), non_neg_integer()) :: Copter.t()
  def latest_reports(%{out: out} = c, before) do
    {new, old} = Enum.split(out, length(out) - before)
    last = fn module -> Enum.find(new, &match?({_, %^module{}}, &1)) end
    keep = [last.(M.MissionItemReached), last.(M.MissionCurrent)]
    new = Enum.filter(new, fn {_, m} = msg -> (not is_struct(m, M.MissionItemReached) and not is_struct(m, M.MissionCurrent)) or msg in keep end)
    %{c | out: new ++ old}
  end

  # A new mission: the old progress means nothing any more. ArduCopter does
  # not report it at once: MISSION_CURRENT tells at its next period.
  @spec changed(Copter.t()) :: Copter.t()
  def changed(c) do
    n = length(MissionServer.items(c.missions))

    cond do
      c.mode == :auto and n > 0 and c.mission_state == 3 -> %{c | current: min(max(c.current, 1), n)}
      true -> %{c | current: 0, resume: nil, jumps: %{}, mission_state: if(n == 0, do: 1, else: 2)}
    end
  end

  # Item 0 as the mission protocol hands it out: home.
  @spec home_item(Copter.t()) :: struct() | nil
  def home_item(%{home: nil}), do: nil

  def home_item(%{home: home}) do
    %M.MissionItemInt{command: 16, frame: 0, x: round(home.lat * 1.0e7), y: round(home.lon * 1.0e7), z: home.alt * 1.0, autocontinue: 1}
  end

  # As ArduPilot's starts_with_takeoff_cmd: DO commands and NAV_DELAY before
  # the first navigation command do not count.
  @spec starts_with_takeoff?(Copter.t()) :: boolean()
  def starts_with_takeoff?(c) do
    case Enum.find(MissionServer.items(c.missions), &(&1.command < 93)) do
      %{command: 22} -> true
      _ -> false
    end
  end

  @spec set_current(Copter.t(), integer()) :: Copter.t()
  def set_current(c, seq) do
    n = length(MissionServer.items(c.missions))
    seq = if seq < 1, do: 1, else: min(seq, max(n, 1))

    cond do
      n == 0 -> c
      c.mode == :auto and c.mission_state == 3 -> start_item(c, seq)
      true -> mission_current(%{c | current: seq, resume: seq})
    end
  end

  @spec mission_current(Copter.t()) :: Copter.t()
  def mission_current(c), do: say(c, Streams.message(c, 42))

  @spec start_item(Copter.t(), integer()) :: Copter.t()
  def start_item(%{burst: burst} = c, _seq) when burst >= @max_items_at_once do
    c = text(%{c | burst: 0}, 3, "Mission: too many commands without navigation")
    complete_mission(c)
  end

  def start_item(c, seq) do
    items = MissionServer.items(c.missions)
    c = %{c | burst: c.burst + 1}

    case Enum.at(items, seq - 1) do
      nil when seq > 1 -> complete_mission(c)
      _ when seq < 1 -> c
      nil -> c
      item -> c |> Map.merge(%{current: seq, mission_state: 3}) |> begin_item(item)
    end
  end

  # ArduPlane cannot hold: at its mission's end it says so and goes home (RTL),
  # circling there; MISSION_CURRENT stays on its last item, complete.
  defp complete_mission(%{config: %{airframe: :plane}} = c) do
    c = mission_current(%{c | mission_state: 5, item: nil, resume: nil})
    c = text(c, 6, "Mission complete, changing mode to RTL")
    %{c | mode: :rtl, nav: if(in_air?(c), do: {:rtl, :climb}, else: :idle)}
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
    c = %{c | item: %{seq: c.current, command: item.command, started_ms: c.time_ms, arrived_ms: nil, take_off_alt: nil, item: item}}
    run_item(c, item)
  end

  @spec item_latlon(struct()) :: {float(), float()}
  def item_latlon(%M.MissionItemInt{x: x, y: y}), do: {x / 1.0e7, y / 1.0e7}
  def item_latlon(%M.MissionItem{x: x, y: y}), do: {x * 1.0, y * 1.0}

  # The item's point; 0,0 means "here", as in ArduPilot.
  @spec item_target(Copter.t(), struct()) :: {float(), float(), float()}
  def item_target(c, item) do
    {n, e} =
      case item_latlon(item) do
        {lat, lon} when lat == 0 and lon == 0 -> {c.n, c.e}
        {lat, lon} -> ne(c, lat, lon)
      end

    alt =
      cond do
        # A rover or boat drives at its own height, whatever the item says.
        Dolphin.Airframe.heights(c.config.airframe) == :own -> c.alt
        item.z == 0 and item.frame in [3, 6, 10, 11] -> c.alt
        true -> target_alt(c, item.frame, item.z)
      end

    {n, e, alt}
  end

  # ArduRover skips a take-off and a landing without a report; ArduSub
  # ignores a take-off, and its landing goes to its point at its depth, rises
  # to the surface there and is reported reached; a rover's RTL drives home
  # (docs/ardupilot.md).
  defp run_item(%{config: %{airframe: airframe}} = c, %{command: command} = item) when airframe in [:rover, :boat, :sub] and command in [20, 21, 22] do
    case {airframe, command} do
      {:sub, 21} -> with({n, e, _} <- item_target(c, %{item | z: 0.0, frame: 3}), do: %{c | nav: {:goto, n, e, c.alt}})
      {ground, 20} when ground in [:rover, :boat] -> with({hn, he} <- home_ne(c), do: %{c | nav: {:goto, hn, he, c.alt}})
      _ -> start_item(%{c | item: nil}, c.current + 1)
    end
  end

  # From the ground ArduCopter climbs at least a metre, whatever height the
  # item asks for (ModeAuto::takeoff_start); the height it climbs to is the
  # item's end.
  defp run_item(c, %{command: 22} = item) do
    {_, _, alt} = item_target(c, %{item | x: 0, y: 0})

    cond do
      in_air?(c) and c.alt >= alt - 0.5 -> item_reached(c)
      in_air?(c) -> %{c | nav: {:climb, c.n, c.e, alt}}
      c.armed -> take_off(c, max(alt, c.alt + @least_take_off))
      # Disarmed on the ground in AUTO: nothing flies until armed, which AUTO refuses.
      true -> c
    end
  end

  # LOITER_TURNS: ArduCopter flies to the edge of the circle, the point of it
  # nearest to where it is, then circles from there.
  defp run_item(c, %{command: 18, param3: radius} = item) do
    {n, e, alt} = item_target(c, item)
    d = distance_to(c, n, e)
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
    {_, c} = Camera.command(c, command, params)
    item_reached(c)
  end

  # Commands flown as no-ops (yaw, relays, servos, ROI...): done at once.
  defp run_item(c, _item), do: item_reached(c)

  defp take_off(c, alt), do: Flight.start_takeoff(%{c | item: %{c.item | take_off_alt: alt}}, alt)

  defp hold_nav(c), do: if(in_air?(c), do: {:hold, c.n, c.e, c.alt}, else: :idle)

  @spec item_reached(Copter.t()) :: Copter.t()
  def item_reached(%{item: %{seq: seq, command: command}} = c) do
    c = say(c, %M.MissionItemReached{seq: seq})
    # ArduCopter says so only for waypoints and timed loiters.
    c = if command in [16, 19], do: text(c, 6, "Reached command ##{seq}"), else: c
    start_item(%{c | item: nil}, seq + 1)
  end

  # The item in progress, checked after each step of flight.
  @spec check_item(Copter.t()) :: Copter.t()
  def check_item(%{mode: :auto, item: %{} = item} = c), do: check_item(c, item.command, item)
  def check_item(c), do: c

  # Done at its height; in the air from then on (ArduCopter's landed state
  # TAKEOFF ends with the take-off), so that touching the ground is a landing.
  defp check_item(c, 22, %{item: i} = item) do
    alt = item.take_off_alt || c |> item_target(%{i | x: 0, y: 0}) |> elem(2)

    if in_air?(c) and c.alt >= alt - 0.5,
      do: item_reached(if(c.landed == :takeoff, do: %{c | landed: :in_air}, else: c)),
      else: c
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
          # A plane circles its loiter (LOITER_TIME at WP_LOITER_RAD: ArduPlane keeps no radius for it).
          c.config.airframe == :plane -> %{c | nav: {:circle, n, e, alt, Plane.flown_radius(if(command == 19, do: 0.0, else: i.param3)), 0.0, nil}, item: %{item | arrived_ms: c.time_ms}}
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

  # A submarine's landing is reached at the surface, a rover's RTL at home.
  defp check_item(%{config: %{airframe: :sub}} = c, 21, _item) do
    top = surface(c)

    case c.nav do
      _ when c.alt >= top - 0.2 -> item_reached(c)
      {:goto, n, e, alt} when alt < top -> if distance_to(c, n, e) <= c.config.wp_radius, do: %{c | nav: {:goto, n, e, top}}, else: c
      _ -> c
    end
  end

  defp check_item(%{config: %{airframe: ground}} = c, 20, _item) when ground in [:rover, :boat] do
    {hn, he} = home_ne(c)
    if distance_to(c, hn, he) <= c.config.wp_radius, do: item_reached(c), else: c
  end

  # RTL and LAND items are reached when the vehicle has landed and disarmed.
  defp check_item(c, _command, _item), do: c

  defp circle_from_edge(c, %{item: i} = item, alt) do
    {n, e, _} = item_target(c, i)
    radius = if c.config.airframe == :plane, do: Plane.flown_radius(i.param3), else: i.param3
    %{c | nav: {:circle, n, e, alt, radius, 0.0, nil}, item: %{item | arrived_ms: c.time_ms}}
  end

  # ArduCopter reports a final RETURN_TO_LAUNCH reached after the disarm, and
  # the mission complete; a final NAV_LAND never: the land item stays current
  # with the mission ACTIVE, announced again (docs/ardupilot.md).
  @spec finish_landing_item(Copter.t()) :: Copter.t()
  def finish_landing_item(%{mode: :auto, item: %{command: 20}} = c), do: item_reached(c)

  # After that disarm ArduCopter resets its mission: item 1 current again, the
  # mission still ACTIVE, "Mission: 1 Takeoff" said (nothing flies: AUTO
  # cannot be armed).
  def finish_landing_item(%{mode: :auto, item: %{command: 21}} = c), do: start_item(%{c | item: nil}, 1)

  def finish_landing_item(c), do: c

  # A mission's NAV_LAND followed by a take-off: ArduCopter flies on armed.
  @spec takeoff_follows_landing?(Copter.t()) :: boolean()
  def takeoff_follows_landing?(%{mode: :auto, item: %{command: 21, seq: seq}} = c) do
    next_nav = c.missions |> MissionServer.items() |> Enum.drop(seq) |> Enum.find(&(&1.command < 100))
    match?(%{command: 22}, next_nav)
  end

  def takeoff_follows_landing?(_c), do: false

  defp dist3(c, n, e, alt), do: :math.sqrt((c.n - n) ** 2 + (c.e - e) ** 2 + (c.alt - alt) ** 2)
end
