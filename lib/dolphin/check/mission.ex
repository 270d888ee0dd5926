defmodule Dolphin.Check.Mission do
  @moduledoc false
  # Pure checks of one mission as a vehicle would be sent it (the items of
  # `Dolphin.Mission.to_items/2`, so that what is checked is what flies):
  # validity (something to fly, positions, heights, limits, take-off and its
  # height and pitch, loiter radii, speeds, jumps, camera) and an energy and
  # time estimate with the simulated ArduCopter's model (Dolphin.Sim.Copter:
  # cruise, climb and descent speeds, hover current times effort, pack
  # capacity).

  alias Dolphin.Geo
  alias Dolphin.Geo.Location
  alias Dolphin.Mission, as: M

  # The simulator's copter (Dolphin.Sim.Copter's defaults, Battery.step/2's effort).
  @cruise 10.0
  @climb 2.5
  @descent 1.5
  @circle_speed 5.0
  @capacity_mah 3300.0
  @hover_current 30.0
  @battery_low 0.2
  # ArduCopter's limits: WPNAV_SPEED up to 20 m/s; loiter radii kept up to 255 m × 10.
  @max_speed 20.0
  @max_radius 2550.0
  # ArduCopter's NAV_TAKEOFF from the ground climbs at least this far above
  # where it stands (ModeAuto::takeoff_start raises a lower target to it).
  @least_take_off 1.0
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
  @type limits :: %{max_distance: number(), max_height: number()}
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
            [_home] -> [nothing_to_fly(name, vehicle)]
            _ -> validity(name, items, vehicle, limits) ++ take_off_heights(name, estimate) ++ endless(name, estimate)
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
    take_off = if airframe in [:rover, :boat, :sub], do: [], else: take_off(name, rest, vehicle)
    positions ++ take_off ++ Enum.flat_map(rest, &params(name, &1, count, vehicle))
  end

  # A submarine's heights are depths (Dolphin.Mission.to_items/2 refuses one
  # above the surface); a rover or boat drives at its own height whatever
  # the item says: a height that differs is said, as a warning.
  defp position_problems(name, item, home, limits, airframe) when airframe in [:sub, :rover, :boat] do
    loc = location(item, home)
    height = loc.h - home.h

    far =
      for p <- position_problems(name, item, home, limits, nil), match?({_, kind, _} when kind in [:position, :too_far], p), do: p

    cond do
      item.seq == 0 or airframe == :sub -> far
      abs(height) > 1.0 -> far ++ [{:warning, :height_ignored, "#{name}: #{describe(item)} is #{metres(height)} above home: a #{airframe} drives at its own height, whatever the item says"}]
      true -> far
    end
  end

  defp position_problems(name, item, home, limits, _airframe) do
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
  defp take_off_heights(name, estimate) do
    for {item, ground, target} <- estimate.low_take_offs do
      {:error, :take_off_height,
       "#{name}: #{describe(item)} goes to #{metres(target)} above sea level, #{metres(target - ground)} above the ground the vehicle takes off from (#{metres(ground)}): " <>
         "ArduCopter climbs only #{metres(@least_take_off)} and flies on from there (a take-off's height is its location's: `take_off location(lat, lon, h)`)"}
    end
  end

  defp params(name, %{command: c} = item, _count, _vehicle) when c in [@loiter_unlim, @loiter_turns, @loiter_time] do
    r = abs(item.param3)

    if r > @max_radius,
      do: [{:error, :loiter_radius, "#{name}: #{describe(item)} has a loiter radius of #{metres(r)} (ArduCopter keeps at most #{metres(@max_radius)})"}],
      else: []
  end

  defp params(name, %{command: @speed} = item, _count, _vehicle) do
    speed = item.param2

    cond do
      speed == -1.0 -> []
      speed <= 0 -> [{:error, :speed, "#{name}: #{describe(item)} sets a speed of #{speed} m/s (a speed is positive)"}]
      speed > @max_speed -> [{:error, :speed, "#{name}: #{describe(item)} sets #{speed} m/s, above ArduCopter's #{@max_speed} m/s"}]
      true -> []
    end
  end

  defp params(name, %{command: @take_off} = item, _count, _vehicle) do
    pitch = item.param1

    if is_number(pitch) and pitch >= @pitches.first and pitch <= @pitches.last,
      do: [],
      else:
        [
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

  # --- energy and time ---

  defp energy(name, estimate, items, vehicle) do
    start = vehicle.battery
    summary = "#{metres(estimate.length_m)}, #{minutes(estimate.time_s)}, #{percent(estimate.battery_used)} of a pack"

    airframe = Map.get(vehicle, :airframe)

    cond do
      # The model below is ArduCopter's (and the simulator's copter): another
      # airframe's energy and time are not judged by it.
      airframe not in [nil, :copter] ->
        [{:note, :energy_model, "#{name}: #{metres(estimate.length_m)} of path; its energy and time are not estimated: the check's model is a copter's, not a #{airframe}'s"}]

      start == nil ->
        [{:note, :energy, "#{name}: #{summary}; the vehicle's battery is not known"}]

      estimate.empty_at != nil ->
        [{:error, :energy, "#{name}: #{summary}, starting with #{percent(start)}: the pack would be empty at #{describe(Enum.at(items, estimate.empty_at))}"}]

      estimate.empty_home ->
        [{:error, :energy, "#{name}: #{summary}, starting with #{percent(start)}: it cannot come home (the pack would be empty on the way back)"}]

      # (A mission that barely flies — going home, say — is what a low battery calls for.)
      estimate.battery_used > 0.01 and start - estimate.battery_used - estimate.home_used < @battery_low ->
        [{:warning, :low_reserve, "#{name}: #{summary}, starting with #{percent(start)}: #{percent(max(start - estimate.battery_used - estimate.home_used, 0.0))} left once home (the low-battery level is #{percent(@battery_low)})"}]

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
  # a jump for ever once), the item where a pack starting at the vehicle's
  # battery would be empty, and what coming home from the last point costs.
  @spec estimate(String.t(), vehicle(), [struct()]) :: map()
  def estimate(name, vehicle, [home | _] = items) do
    home_loc = location(home, nil)
    # Where the vehicle is when the mission starts: where the last one left it, else at home.
    start = %{at: Map.get(vehicle, :at) || home_loc, airborne?: vehicle.airborne?, speed: @cruise, length: 0.0, time: 0.0, used: 0.0, empty_at: nil, path: [], low_take_offs: []}
    flown = Enum.reduce(flight_order(items), start, fn item, acc -> step(item, home_loc, acc, vehicle.battery) end)
    {back_time, back_as, back_length} = if flown.airborne?, do: leg(flown.at, %{home_loc | h: flown.at.h}, flown.speed) |> land(flown.at.h, home_loc), else: {0.0, 0.0, 0.0}
    back_used = fraction(back_as)
    ending = M.ending(items)

    %{
      mission: name,
      vehicle: vehicle.id,
      length_m: flown.length,
      time_s: flown.time,
      battery_used: flown.used,
      battery_start: vehicle.battery,
      ending: ending,
      lands?: not flown.airborne?,
      home_used: back_used,
      home_length_m: back_length,
      home_time_s: back_time,
      empty_at: flown.empty_at,
      start_at: start.at,
      path: Enum.reverse(flown.path),
      low_take_offs: flown.low_take_offs |> Enum.reverse() |> Enum.uniq_by(fn {item, _, _} -> item.seq end),
      empty_home: vehicle.battery != nil and flown.empty_at == nil and flown.used + back_used > vehicle.battery
    }
  end

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

  # From the ground ArduCopter climbs at least its least take-off; in the
  # air a take-off to no more height is done at once.
  defp step(%{command: @take_off} = item, home, acc, start) do
    target = location(item, home)
    low? = not acc.airborne? and target.h - acc.at.h < @least_take_off
    climb = if acc.airborne?, do: max(target.h - acc.at.h, 0.0), else: max(target.h - acc.at.h, @least_take_off)
    acc = if low?, do: %{acc | low_take_offs: [{item, acc.at.h, target.h} | acc.low_take_offs]}, else: acc
    # Spooling up and climbing straight up, at the climb's effort.
    time = 3.0 + climb / @climb
    add(%{acc | at: %{acc.at | h: acc.at.h + climb}, airborne?: true}, item, time, amps(0.0, @climb) * time, climb, start)
  end

  defp step(%{command: c} = item, home, acc, start) when c in [@waypoint, @loiter_unlim, @loiter_turns, @loiter_time] do
    target = location(item, home)
    {time, mah, length} = leg(acc.at, target, acc.speed)
    {extra_time, extra_mah, extra_length} = loiter(item)
    add(%{acc | at: target}, item, time + extra_time, mah + extra_mah, length + extra_length, start)
  end

  defp step(%{command: c} = item, home, acc, start) when c in [@land, @rtl] do
    target = if c == @rtl or not positioned?(item), do: home, else: location(item, home)
    {time, mah, length} = leg(acc.at, %{target | h: acc.at.h}, acc.speed) |> land(acc.at.h, home)
    add(%{acc | at: %{target | h: home.h}, airborne?: false}, item, time, mah, length, start)
  end

  defp step(%{command: @delay} = item, _home, acc, start) do
    time = max(item.param1, 0.0)
    add(acc, item, time, if(acc.airborne?, do: amps(0.0, 0.0) * time, else: 0.0), 0.0, start)
  end

  defp step(%{command: @speed} = item, _home, acc, _start) when item.param2 > 0, do: %{acc | speed: item.param2}
  defp step(_item, _home, acc, _start), do: acc

  defp loiter(%{command: @loiter_time, param1: seconds}), do: {seconds, amps(0.0, 0.0) * seconds, 0.0}

  defp loiter(%{command: @loiter_turns, param1: turns, param3: radius}) do
    length = 2 * :math.pi() * abs(radius) * turns
    time = length / @circle_speed
    {time, amps(@circle_speed, 0.0) * time, length}
  end

  defp loiter(_item), do: {0.0, 0.0, 0.0}

  # A straight leg: across at the speed, up or down at the climb or descent
  # rate, both at once (the longer one sets the time).
  defp leg(%Location{} = from, %Location{} = to, speed) do
    across = Geo.distance(from, to)
    dz = to.h - from.h
    t_across = across / speed
    t_up = if dz > 0, do: dz / @climb, else: -dz / @descent
    time = max(t_across, t_up)
    v = if time > 0, do: across / time, else: 0.0
    vz = if time > 0 and dz > 0, do: dz / time, else: 0.0
    {time, amps(v, vz) * time, :math.sqrt(across * across + dz * dz)}
  end

  # Then straight down to the ground at the descent rate, hovering.
  defp land({time, mah, length}, from_h, %Location{h: ground}) do
    down = max(from_h - ground, 0.0)
    t = down / @descent
    {time + t, mah + amps(0.0, 0.0) * t, length + down}
  end

  # Amp-seconds per second at a horizontal and climb speed (Battery.step/2).
  defp amps(v, vz), do: @hover_current * (1.0 + 0.1 * v / 10 + 0.2 * max(vz, 0) / 2.5)

  # Amp-seconds as a fraction of the pack (mAh = A·s / 3.6).
  defp fraction(amp_seconds), do: amp_seconds / 3.6 / @capacity_mah

  defp add(acc, item, time, amp_seconds, length, start) do
    used = acc.used + fraction(amp_seconds)
    empty_at = if acc.empty_at == nil and start != nil and used > start, do: item.seq, else: acc.empty_at
    %{acc | time: acc.time + time, used: used, length: acc.length + length, empty_at: empty_at, path: [{acc.time + time, acc.at, acc.airborne?, item.seq} | acc.path]}
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
