defmodule Dolphin.Check.Mission do
  @moduledoc false
  # Pure checks of one mission as a vehicle would be sent it (the items of
  # `Dolphin.Mission.to_items/2`, so that what is checked is what flies):
  # validity (something to fly, positions, heights and depths, limits,
  # take-off and its height and pitch, loiter radii, speeds, a plane's turns,
  # jumps, camera) and an energy and time estimate with the vehicle's
  # airframe's model (Dolphin.Airframe: speeds, climb and descent, current
  # drawn, pack capacity — the simulator's figures, held to each SITL).

  alias Dolphin.{Airframe, Fence, Geo}
  alias Dolphin.Geo.Shapes
  alias Dolphin.Geo.Location
  alias Dolphin.Mission, as: M
  alias Dolphin.Mission.Survey

  @battery_low 0.2
  # The deepest a submarine is sent unless the check is told otherwise
  # (`:max_depth`): a BlueROV2's rated depth.
  @max_depth 100
  # NAV_TAKEOFF's param1 is ArduPlane's least climb angle (ArduCopter ignores it).
  @pitches 0..90

  @waypoint 16
  @loiter_unlim 17
  @loiter_turns 18
  @loiter_time 19
  @rtl 20
  @land 21
  @take_off 22
  @delay 93
  @jump 177
  @speed 178
  @photo [2000, 2001]
  @absolute_frames [0, 5]
  @relative_frames [3, 6]

  # position: its home; at: where it is now (nil: at home).
  @type vehicle :: %{
          required(:id) => non_neg_integer(),
          required(:payloads) => [atom()],
          required(:battery) => float() | nil,
          required(:position) => Location.t() | nil,
          required(:airborne?) => boolean(),
          optional(:at) => Location.t() | nil,
          optional(:airframe) => atom() | nil
        }
  @type limits :: %{required(:max_distance) => number(), required(:max_height) => number(), optional(:max_depth) => number()}
  @type problem :: {:error | :warning | :note, atom(), String.t()}
  @type estimate :: %{
          mission: String.t(),
          vehicle: non_neg_integer(),
          length_m: float(),
          time_s: float(),
          battery_used: float(),
          battery_start: float() | nil,
          ending: M.ending(),
          lands?: boolean()
        }

  @doc false
  # The problems of `mission` flown by `vehicle`, and its estimate (nil when
  # its items cannot even be made).
  # Energy problems are apart: they hold only if the flight is not cut short
  # (by `until`, say) before the pack runs out, which the dry run decides.
  @spec check(M.t(), vehicle(), limits()) :: {[problem()], [problem()], estimate() | nil}
  def check(%M{} = mission, vehicle, limits) do
    home_opt = if mission.home == nil and vehicle.position, do: [home: vehicle.position], else: []

    case items(mission, [airframe: Map.get(vehicle, :airframe)] ++ home_opt) do
      {:ok, items} ->
        name = "mission #{inspect(mission.name)} on vehicle #{vehicle.id}"
        estimate = estimate(mission.name, vehicle, items)

        problems =
          case items do
            [_home] ->
              [nothing_to_fly(name, vehicle)]

            _ ->
              validity(name, items, vehicle, limits) ++
                turns(name, mission, vehicle) ++ fence(name, mission.fence, estimate, items, vehicle) ++ take_off_heights(name, estimate, vehicle) ++ endless(name, estimate)
          end

        {problems, energy(name, estimate, items, vehicle), Map.drop(estimate, [:empty_at, :empty_home, :low_take_offs])}

      {:error, message} ->
        kind = if message =~ "jump", do: :jump, else: :mission
        {[{:error, kind, "mission #{inspect(mission.name)}: #{message}"}], [], nil}
    end
  end

  # Dolphin.Mission.to_items/2 refuses a jump to a missing item or a mission
  # with no home to take: the same words, as a finding.
  defp items(mission, opts) do
    {:ok, M.to_items(mission, opts)}
  rescue
    e in ArgumentError -> {:error, Exception.message(e)}
  end

  # --- validity ---

  defp validity(name, [home | rest] = items, vehicle, limits) do
    home_loc = location(home, nil)
    count = length(items)

    airframe = Map.get(vehicle, :airframe)
    positions = for item <- items, positioned?(item), problem <- position_problems(name, item, home_loc, limits, airframe), do: problem
    take_off = if Airframe.takes_off?(airframe), do: take_off(name, rest, vehicle), else: []
    positions ++ take_off ++ Enum.flat_map(rest, &params(name, &1, count, vehicle))
  end

  # A submarine's heights are depths (Dolphin.Mission.to_items/2 refuses one
  # above the surface), no deeper than the limit; a rover or boat drives at
  # its own height whatever the item says: a height that differs is said, as
  # a warning.
  defp position_problems(name, item, home, limits, airframe) do
    case Airframe.heights(airframe) do
      :altitude -> altitude_problems(name, item, home, limits)
      heights -> surface_problems(name, item, home, limits, airframe, heights)
    end
  end

  defp surface_problems(name, item, home, limits, airframe, heights) do
    height = location(item, home).h - home.h
    far = for p <- altitude_problems(name, item, home, limits), match?({_, kind, _} when kind in [:position, :too_far], p), do: p
    max_depth = Map.get(limits, :max_depth, @max_depth)

    cond do
      item.seq == 0 ->
        far

      heights == :depth and -height > max_depth ->
        far ++ [{:error, :too_deep, "#{name}: #{describe(item)} is #{metres(-height)} deep (limit #{metres(max_depth)})"}]

      heights == :own and abs(height) > 1.0 ->
        far ++ [{:warning, :height_ignored, "#{name}: #{describe(item)} is #{metres(height)} above home: a #{airframe} drives at its own height, whatever the item says"}]

      true ->
        far
    end
  end

  defp altitude_problems(name, item, home, limits) do
    {lat, lon} = {item.x / 1.0e7, item.y / 1.0e7}
    what = "#{name}: #{describe(item)}"

    cond do
      lat < -90 or lat > 90 or lon < -180 or lon > 180 ->
        [{:error, :position, "#{what} is not on Earth (latitude #{lat}, longitude #{lon})"}]

      item.seq > 0 and lat == 0 and lon == 0 ->
        [{:warning, :position, "#{what} is at latitude 0, longitude 0, which ArduPilot takes as \"where the vehicle is\" (if a position was meant, it was never set)"}]

      item.seq == 0 ->
        []

      true ->
        loc = location(item, home)
        height = loc.h - home.h
        distance = Geo.distance(home, loc)

        Enum.reject(
          [
            if(height < -0.5, do: {:error, :below_ground, "#{what} is #{metres(-height)} below the home's ground (#{metres(loc.h)} above sea level, home at #{metres(home.h)})"}),
            if(height > limits.max_height, do: {:error, :too_high, "#{what} is #{metres(height)} above home (limit #{metres(limits.max_height)})"}),
            if(distance > limits.max_distance, do: {:error, :too_far, "#{what} is #{metres(distance)} from home (limit #{metres(limits.max_distance)})"})
          ],
          &is_nil/1
        )
    end
  end

  # Only a home: the vehicle is sent no item, and ArduCopter starts no mission.
  defp nothing_to_fly(name, vehicle) do
    where = if vehicle.airborne?, do: "", else: " (on the ground it would not even take off)"
    {:error, :empty_mission, "#{name}: nothing to fly: the mission has no item after its home#{where}"}
  end

  # A vehicle on the ground must take off before it flies to anything; with
  # no take-off at all ArduCopter refuses the mission ("Auto: Missing Takeoff Cmd").
  defp take_off(name, items, %{airborne?: false}) do
    first = Enum.find(items, &(&1.command in [@waypoint, @loiter_unlim, @loiter_turns, @loiter_time, @take_off, @rtl]))

    cond do
      first == nil and not Enum.any?(items, &(&1.command == @land)) ->
        [{:error, :no_take_off, "#{name}: no take-off, and the vehicle starts on the ground: there is nothing it can fly (#{Enum.map_join(items, ", ", &describe/1)})"}]

      first != nil and first.command != @take_off ->
        [{:error, :no_take_off, "#{name}: no take-off before #{describe(first)}, and the vehicle starts on the ground"}]

      true ->
        []
    end
  end

  defp take_off(_name, _items, _vehicle), do: []

  # A take-off from the ground to no height: ArduCopter climbs its least
  # take-off and flies on from there, at the ground's height.
  defp take_off_heights(name, estimate, vehicle) do
    firmware = Airframe.of(Map.get(vehicle, :airframe)).firmware()

    for {item, ground, target, least} <- estimate.low_take_offs do
      {:error, :take_off_height,
       "#{name}: #{describe(item)} goes to #{metres(target)} above sea level, #{metres(target - ground)} above the ground the vehicle takes off from (#{metres(ground)}): " <>
         "#{firmware} climbs only #{metres(least)} and flies on from there (a take-off's height is its location's: `take_off location(lat, lon, h)`)"}
    end
  end

  defp params(name, %{command: c} = item, _count, vehicle) when c in [@loiter_unlim, @loiter_turns, @loiter_time] do
    r = abs(item.param3)
    airframe = Map.get(vehicle, :airframe)
    module = Airframe.of(airframe)
    p = module.performance()
    flown = abs(module.flown_radius(p, item.param3))

    cond do
      r > p.max_loiter_radius ->
        [{:error, :loiter_radius, "#{name}: #{describe(item)} has a loiter radius of #{metres(r)} (#{module.firmware()} keeps at most #{metres(p.max_loiter_radius)})"}]

      c == @loiter_turns and r >= 1 and flown > r * 1.5 ->
        [{:warning, :loiter_radius, "#{name}: #{describe(item)} circles at a radius of #{metres(r)}: a #{airframe} flies it at about #{metres(flown)} (it turns no tighter)"}]

      true ->
        []
    end
  end

  defp params(name, %{command: @speed} = item, _count, vehicle) do
    speed = item.param2
    module = Airframe.of(Map.get(vehicle, :airframe))
    p = module.performance()

    cond do
      speed == -1.0 ->
        []

      speed <= 0 ->
        [{:error, :speed, "#{name}: #{describe(item)} sets a speed of #{speed} m/s (a speed is positive)"}]

      p.max_speed != nil and speed > p.max_speed ->
        [{:error, :speed, "#{name}: #{describe(item)} sets #{speed} m/s, above #{module.firmware()}'s #{p.max_speed} m/s"}]

      p.min_speed != nil and speed < p.min_speed ->
        [{:error, :speed, "#{name}: #{describe(item)} sets #{speed} m/s, below #{module.firmware()}'s least airspeed of #{p.min_speed} m/s: it would stall"}]

      true ->
        []
    end
  end

  defp params(name, %{command: @take_off} = item, _count, _vehicle) do
    pitch = item.param1

    if is_number(pitch) and pitch >= @pitches.first and pitch <= @pitches.last,
      do: [],
      else: [
        {:error, :take_off_pitch,
         "#{name}: #{describe(item)} has a pitch of #{pitch_text(pitch)}°: a take-off's pitch is its angle of climb, #{@pitches.first}..#{@pitches.last}° " <>
           "(the second argument of `take_off location, pitch`; its height is the location's)"}
      ]
  end

  defp params(name, %{command: @jump} = item, count, _vehicle) do
    target = trunc(item.param1)

    if target < 1 or target >= count or target == item.seq,
      do: [{:error, :jump, "#{name}: #{describe(item)} jumps to item #{target}, which is not another item of the mission (1..#{count - 1})"}],
      else: []
  end

  defp params(name, %{command: c} = item, _count, vehicle) when c in @photo do
    if :camera in vehicle.payloads,
      do: [],
      else: [{:error, :no_camera, "#{name}: #{describe(item)} takes photos, and vehicle #{vehicle.id} has no camera"}]
  end

  defp params(_name, _item, _count, _vehicle), do: []

  # A survey's passes end in a half turn into the next one: a vehicle that
  # cannot turn that tight (a plane: its turn radius at the speed it flies
  # the survey, at its bank limit) overshoots every pass end and misses the
  # ground between — the survey does not cover what it says.
  defp turns(name, %M{commands: commands}, vehicle) do
    airframe = Map.get(vehicle, :airframe)
    module = Airframe.of(airframe)
    p = module.performance()

    {problems, _speed} =
      Enum.reduce(commands, {[], p.cruise_speed}, fn
        %{kind: :speed, args: args}, {acc, speed} ->
          {acc, if(is_number(args[:speed]) and args[:speed] > 0 and args[:speed_type] in [0, 1], do: args[:speed] * 1.0, else: speed)}

        %{kind: :survey_area, args: a} = command, {acc, speed} ->
          passes = Survey.pass_count(a[:width], a[:spacing])
          apart = a[:width] / passes
          radius = module.turn_radius(p, speed)

          if passes > 1 and apart < 2 * radius,
            do: {[survey_turn(name, command, apart, radius, speed, airframe) | acc], speed},
            else: {acc, speed}

        _other, acc ->
          acc
      end)

    Enum.reverse(problems)
  end

  defp survey_turn(name, command, apart, radius, speed, airframe) do
    {:error, :turn_radius,
     "#{name}: #{inspect(command)} puts its passes #{metres(apart)} apart, and a #{airframe} at #{Float.round(speed, 1)} m/s turns no tighter than a #{metres(radius)} radius: " <>
       "it cannot turn from one pass into the next (they must be at least #{metres(2 * radius)} apart: a wider spacing, or a lower speed)"}
  end

  # --- the fence ---

  # The mission as it would fly (the estimate's path: each item's point in
  # flight order, its loiter circles, the way home when it does not land)
  # against the fence: a leg that leaves an inclusion zone or enters an
  # exclusion zone, a point above the ceiling or, in flight, below the
  # floor — each with where; a fence that home itself breaches.
  defp fence(_name, nil, _estimate, _items, _vehicle), do: []

  defp fence(name, %Fence{} = fence, estimate, [home_item | _] = items, vehicle) do
    home = location(home_item, nil)
    by_seq = Map.new(items, &{&1.seq, &1})
    airframe = Map.get(vehicle, :airframe)

    setup = for why <- Fence.problems(fence, home), do: {:error, :fence, "#{name}: the fence's #{why}"}

    legs =
      estimate.path
      |> Enum.map(fn {_t, at, airborne?, seq} -> {at, airborne?, Map.get(by_seq, seq)} end)
      |> then(&[{estimate.start_at, false, nil} | &1])
      |> Enum.chunk_every(2, 1, :discard)
      |> Enum.flat_map(fn [{from, _, _}, {to, airborne?, item}] -> [{from, to, item, airborne?} | circle_legs(to, item, airborne?, airframe)] end)

    back = if estimate.lands?, do: [], else: [{List.last(Enum.map(legs, &elem(&1, 1))) || estimate.start_at, home, :home, true}]

    crossings = Enum.flat_map(legs ++ back, &leg_breach(fence, &1))
    heights = Enum.flat_map(estimate.path, &height_breach(fence, &1, by_seq, home))

    # A fence home itself breaches says it all: every leg would.
    if setup != [], do: setup, else: Enum.map(Enum.uniq(crossings ++ heights), fn why -> {:error, :fence, "#{name}: #{why}"} end)
  end

  # A loiter's circle, as legs round it (16 of them), where the airframe circles.
  defp circle_legs(centre, %{command: c} = item, true, airframe) when c in [@loiter_unlim, @loiter_turns, @loiter_time] do
    radius = abs(Airframe.flown_radius(airframe, item.param3))

    if c == @loiter_turns or Airframe.performance(airframe).hold_speed > 0 do
      points = for k <- 0..16, do: Geo.offset(centre, radius * :math.cos(k * :math.pi() / 8), radius * :math.sin(k * :math.pi() / 8))
      for [a, b] <- Enum.chunk_every(points, 2, 1, :discard), do: {a, b, item, true}
    else
      []
    end
  end

  defp circle_legs(_centre, _item, _airborne?, _airframe), do: []

  defp leg_breach(fence, {from, to, item, _airborne?}) do
    exits = for {zone, i} <- Enum.with_index(fence.include, 1), {t, at} <- [Shapes.exit(zone, from, to)], do: {t, at, "leaves inclusion zone #{i}"}
    entries = for {zone, i} <- Enum.with_index(fence.exclude, 1), {t, at} <- [Shapes.entry(zone, from, to)], do: {t, at, "enters exclusion zone #{i}"}

    for {_t, at, what} <- Enum.sort_by(exits ++ entries, &elem(&1, 0)) |> Enum.take(1) do
      "the way #{leg_name(item)} #{what} at #{point(at)}"
    end
  end

  defp height_breach(fence, {_t, at, airborne?, seq}, by_seq, home) do
    item = Map.get(by_seq, seq)
    height = at.h - home.h
    cruising? = airborne? and item != nil and item.command not in [@take_off, @land, @rtl]

    cond do
      fence.max_altitude != nil and height > fence.max_altitude + 0.5 ->
        ["#{describe(item)} is #{metres(height)} above home, over the fence's max_altitude of #{metres(fence.max_altitude)}"]

      fence.min_altitude != nil and cruising? and height < fence.min_altitude - 0.5 ->
        ["#{describe(item)} is #{metres(height)} above home, under the fence's min_altitude of #{metres(fence.min_altitude)}"]

      true ->
        []
    end
  end

  defp leg_name(nil), do: "from where it starts"
  defp leg_name(:home), do: "home from the mission's end"
  defp leg_name(item), do: "to #{describe(item)}"

  defp point(at), do: "#{Float.round(at.lat, 6)}, #{Float.round(at.lon, 6)}"

  # --- energy and time ---

  defp energy(name, estimate, items, vehicle) do
    start = vehicle.battery
    summary = "#{metres(estimate.length_m)}, #{minutes(estimate.time_s)}, #{percent(estimate.battery_used)} of a pack"
    back = if Airframe.takes_off?(Map.get(vehicle, :airframe)), do: "once home", else: "back home"

    cond do
      start == nil ->
        [{:note, :energy, "#{name}: #{summary}; the vehicle's battery is not known"}]

      estimate.empty_at != nil ->
        [{:error, :energy, "#{name}: #{summary}, starting with #{percent(start)}: the pack would be empty at #{describe(Enum.at(items, estimate.empty_at))}"}]

      estimate.empty_home ->
        [{:error, :energy, "#{name}: #{summary}, starting with #{percent(start)}: it cannot come home (the pack would be empty on the way back)"}]

      # (A mission that barely flies — going home, say — is what a low battery calls for.)
      estimate.battery_used > 0.01 and start - estimate.battery_used - estimate.home_used < @battery_low ->
        [
          {:warning, :low_reserve,
           "#{name}: #{summary}, starting with #{percent(start)}: #{percent(max(start - estimate.battery_used - estimate.home_used, 0.0))} left #{back} (the low-battery level is #{percent(@battery_low)})"}
        ]

      true ->
        []
    end
  end

  defp endless(name, %{ending: {:loiter_forever, seq}}),
    do: [{:note, :endless, "#{name}: ends in an endless loiter (item #{seq}): it flies until stopped, so its battery use depends on what stops it"}]

  defp endless(name, %{ending: {:loops_forever, seq}}),
    do: [{:note, :endless, "#{name}: loops for ever (item #{seq}): it flies until stopped, so its battery use depends on what stops it"}]

  defp endless(_name, _estimate), do: []

  @doc false
  # Length, time and battery use of flying `items` from home (jumps followed,
  # a jump for ever once) with the vehicle's airframe's model, the item where
  # a pack starting at the vehicle's battery would be empty, what coming home
  # from the last point costs, and what holding costs per second (past the
  # end of a mission that does not end by itself).
  @spec estimate(String.t(), vehicle(), [struct()]) :: map()
  def estimate(name, vehicle, [home | _] = items) do
    airframe = Map.get(vehicle, :airframe)
    module = Airframe.of(airframe)
    model = %{module: module, p: module.performance(), heights: module.heights()}
    home_loc = location(home, nil)
    # Where the vehicle is when the mission starts: where the last one left
    # it, else where it stands. (A vehicle that does not take off is under
    # way from the start.)
    under_way? = vehicle.airborne? or not module.takes_off?()

    start = %{
      at: Map.get(vehicle, :at) || stands(vehicle, home_loc),
      airborne?: under_way?,
      speed: model.p.cruise_speed,
      capacity: model.p.capacity_mah,
      flies?: module.takes_off?(),
      length: 0.0,
      time: 0.0,
      used: 0.0,
      empty_at: nil,
      path: [],
      low_take_offs: []
    }

    flown = Enum.reduce(flight_order(items), start, fn item, acc -> step(item, home_loc, acc, vehicle.battery, model) end)
    {back_time, back_as, back_length} = if flown.airborne?, do: land(model, flown.at, home_loc, flown.speed, false), else: {0.0, 0.0, 0.0}
    back_used = fraction(model, back_as)
    ending = M.ending(items, airframe)

    %{
      mission: name,
      vehicle: vehicle.id,
      airframe: airframe,
      length_m: flown.length,
      time_s: flown.time,
      battery_used: flown.used,
      battery_start: vehicle.battery,
      ending: ending,
      lands?: not flown.airborne?,
      home_used: back_used,
      home_length_m: back_length,
      home_time_s: back_time,
      hold_per_s: fraction(model, holding(model)),
      empty_at: flown.empty_at,
      start_at: start.at,
      path: Enum.reverse(flown.path),
      low_take_offs: flown.low_take_offs |> Enum.reverse() |> Enum.uniq_by(fn {item, _, _, _} -> item.seq end),
      empty_home: vehicle.battery != nil and flown.empty_at == nil and flown.used + back_used > vehicle.battery
    }
  end

  # Where a vehicle on the ground stands: its own position (a copter climbs
  # from where it is), at the height of the mission's home when it is
  # within a few metres of it (where the mission's heights are measured
  # from); none known, at the home.
  defp stands(%{position: %Location{} = p}, home), do: if(abs(p.h - home.h) < 5.0, do: %{p | h: home.h}, else: p)
  defp stands(_vehicle, home), do: home

  # The items in the order they are flown: jumps repeated as often as they
  # say (a jump for ever: once round the loop), skipping home.
  defp flight_order([_home | rest] = items) do
    by_seq = Map.new(items, &{&1.seq, &1})
    walk(first_seq(rest), by_seq, %{}, [], 0) |> Enum.reverse()
  end

  defp first_seq([]), do: nil
  defp first_seq([item | _]), do: item.seq

  defp walk(nil, _by_seq, _done, acc, _n), do: acc
  defp walk(_seq, _by_seq, _done, acc, n) when n > 10_000, do: acc

  defp walk(seq, by_seq, done, acc, n) do
    case Map.fetch(by_seq, seq) do
      :error ->
        acc

      {:ok, %{command: @jump} = item} ->
        repeat = if item.param2 < 0, do: 1, else: trunc(item.param2)
        taken = Map.get(done, seq, 0)

        if taken < repeat,
          do: walk(trunc(item.param1), by_seq, Map.put(done, seq, taken + 1), acc, n + 1),
          else: walk(seq + 1, by_seq, done, acc, n + 1)

      {:ok, item} ->
        walk(seq + 1, by_seq, done, [item | acc], n + 1)
    end
  end

  # From the ground it climbs at least its least take-off (ArduCopter), as
  # its airframe climbs out; in the air a take-off to no more height is done at once.
  defp step(%{command: @take_off} = item, home, acc, start, m) do
    target = location(item, home)
    least = m.p.least_take_off
    low? = not acc.airborne? and least > 0 and target.h - acc.at.h < least
    climb = if acc.airborne?, do: max(target.h - acc.at.h, 0.0), else: max(target.h - acc.at.h, least)
    acc = if low?, do: %{acc | low_take_offs: [{item, acc.at.h, target.h, least} | acc.low_take_offs]}, else: acc
    {rate, ground_speed, lead_s} = m.module.climb_out(m.p, item.param1)
    climbing = climb / rate
    time = lead_s + climbing
    amp_seconds = current(m, ground_speed, rate, true) * time
    add(%{acc | at: %{acc.at | h: acc.at.h + climb}, airborne?: true}, item, time, amp_seconds, climb + ground_speed * climbing, start)
  end

  defp step(%{command: c} = item, home, acc, start, m) when c in [@waypoint, @loiter_unlim, @loiter_turns, @loiter_time] do
    target = at_height(m, location(item, home), acc.at)
    {time, amp_seconds, length} = leg(m, acc.at, target, acc.speed)
    {extra_time, extra_as, extra_length} = loiter(m, item)
    add(%{acc | at: target}, item, time + extra_time, amp_seconds + extra_as, length + extra_length, start)
  end

  defp step(%{command: c} = item, home, acc, start, m) when c in [@land, @rtl] do
    target = if c == @rtl or not positioned?(item), do: home, else: location(item, home)
    {time, amp_seconds, length} = land(m, acc.at, target_ground(m, target, home), acc.speed, true)
    add(%{acc | at: target_ground(m, target, home), airborne?: not m.module.takes_off?()}, item, time, amp_seconds, length, start)
  end

  defp step(%{command: @delay} = item, _home, acc, start, m) do
    time = max(item.param1, 0.0)
    add(acc, item, time, if(acc.airborne?, do: holding(m) * time, else: 0.0), 0.0, start)
  end

  defp step(%{command: @speed} = item, _home, acc, _start, _m) when item.param2 > 0, do: %{acc | speed: item.param2}
  defp step(_item, _home, acc, _start, _m), do: acc

  # A rover or boat drives at its own height, whatever the item says.
  defp at_height(%{heights: :own}, target, at), do: %{target | h: at.h}
  defp at_height(_m, target, _at), do: target

  # Where a landing ends: on the ground at home's height; a submarine at the surface.
  defp target_ground(%{heights: :own}, target, home), do: %{target | h: home.h}
  defp target_ground(_m, target, home), do: %{target | h: home.h}

  # A loiter's time: held for its seconds, or its turns round the circle it flies.
  defp loiter(m, %{command: @loiter_time, param1: seconds}), do: {seconds, holding(m) * seconds, m.p.hold_speed * seconds}

  defp loiter(m, %{command: @loiter_turns, param1: turns, param3: radius}) do
    length = 2 * :math.pi() * abs(m.module.flown_radius(m.p, radius)) * turns
    time = length / m.p.circle_speed
    {time, current(m, m.p.circle_speed, 0.0, true) * time, length}
  end

  defp loiter(_m, _item), do: {0.0, 0.0, 0.0}

  # A straight leg: across at the speed, up or down at the climb or descent
  # rate, both at once (the longer one sets the time).
  defp leg(m, %Location{} = from, %Location{} = to, speed) do
    across = Geo.distance(from, to)
    dz = to.h - from.h
    t_across = across / speed
    t_up = if dz > 0, do: dz / m.p.climb_speed, else: -dz / m.p.descent_speed
    time = max(t_across, t_up)
    v = if time > 0, do: across / time, else: 0.0
    vz = if time > 0 and dz > 0, do: dz / time, else: 0.0
    {time, current(m, v, vz, true) * time, :math.sqrt(across * across + dz * dz)}
  end

  # A landing at `to` (on the ground): across at its height then straight
  # down (or up: a submarine surfacing), holding — or down a glide slope,
  # then the wait on the ground for its own disarm.
  defp land(%{p: %{landing: :glide}} = m, from, to, speed, disarm?) do
    {time, amp_seconds, length} = leg(m, from, to, speed)
    {time + if(disarm?, do: m.p.landed_disarm_s, else: 0.0), amp_seconds, length}
  end

  defp land(m, from, to, speed, _disarm?) do
    {time, amp_seconds, length} = leg(m, from, %{to | h: from.h}, speed)
    dz = to.h - from.h
    t = if dz > 0, do: dz / m.p.climb_speed, else: -dz / m.p.descent_speed
    {time + t, amp_seconds + holding(m) * t, length + abs(dz)}
  end

  defp current(m, v, vz, airborne?), do: m.module.current(m.p, v, vz, airborne?)

  # Amperes while holding where it is (a plane circling).
  defp holding(m), do: current(m, m.p.hold_speed, 0.0, true)

  # Amp-seconds as a fraction of the pack (mAh = A·s / 3.6).
  defp fraction(m, amp_seconds), do: amp_seconds / 3.6 / m.p.capacity_mah

  defp add(acc, item, time, amp_seconds, length, start) do
    used = acc.used + amp_seconds / 3.6 / acc.capacity
    empty_at = if acc.empty_at == nil and start != nil and used > start, do: item.seq, else: acc.empty_at
    %{acc | time: acc.time + time, used: used, length: acc.length + length, empty_at: empty_at, path: [{acc.time + time, acc.at, acc.airborne? and acc.flies?, item.seq} | acc.path]}
  end

  # --- items ---

  defp positioned?(item), do: item.frame in @absolute_frames or item.frame in @relative_frames

  defp location(item, home) do
    h = if item.frame in @relative_frames and home, do: home.h + item.z, else: item.z * 1.0
    %Location{lat: item.x / 1.0e7, lon: item.y / 1.0e7, h: h}
  end

  defp describe(item), do: "item #{item.seq} (#{M.item_name(item)})"

  defp pitch_text(p) when is_float(p) and p == trunc(p), do: Integer.to_string(trunc(p))
  defp pitch_text(p) when is_number(p), do: to_string(p)
  defp pitch_text(p), do: inspect(p)

  defp metres(m), do: "#{round(m)} m"
  defp minutes(s) when s < 120, do: "#{round(s)} s"
  defp minutes(s), do: "#{Float.round(s / 60, 1)} min"
  defp percent(f), do: "#{round(f * 100)} %"
end
