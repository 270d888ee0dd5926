# What the report's Listing 4 wanted: two areas watched all the time. Over each
# area a vehicle circles at 50 to 80 m; from the first arrival on, there is
# always one there: its relief takes off while it still has battery to wait,
# flies out, and only when the relief is on station (within the circle's
# radius plus 20 m of the point, at its watch height) does the vehicle on
# station fly home. The three vehicles of a ring circle 15 m apart in height
# (50, 65, 80 m), so a relief joins the circle above or below the one it
# relieves, never at its height (the live separation monitor, which keeps our
# vehicles 20 m across or 10 m in height apart, would hold it short of the
# circle otherwise).
#
#   mix dolphin.run examples/relay_continuous.exs --sim 6 --speedup 50
#
# Each area has a ring of three vehicles: each waits for the one before it to
# be on station and down to 55 % (and for its own battery to be at 90 %),
# watches until the next one is on station, returns, recharges, and waits for
# its turn again. The first vehicle of each ring starts at once. Everything
# runs in one `execute`, each vehicle with its own chain of tasks; after
# `rounds` turns of each vehicle the last one on station, with no relief to
# come, flies home at 30 % and the script ends (about 30 minutes of clock time).
#
# Why three, from the simulator's battery (3300 mAh; 30 A hovering, about
# 0.25 %/s; 0.3 %/s climbing at 2.5 m/s, 0.28 %/s cruising at 10 m/s, 0.27 %/s
# circling; charging 0.5 %/s on the ground at home):
#   out:       climb 50 m (20 s) + 300 m to the point (about 35 s)  ~ 15 %, 55 s
#              (65 and 80 m: 6 and 12 s more, 2 and 4 % more)
#   on station from about 85 % to about 43 % (the relief, launched at
#   55 %, arrives some 50 s later)                                 ~ 165 s
#   back:      300 m (35 s) + descend 50 m at 1.5 m/s (33 s) + the
#              10 s before disarming                               ~ 18 %, 80 s
#   recharge:  from about 25 % to 90 %                             ~ 130 s
# A vehicle is away from station for 55 + 80 + 130 = 265 s, while the other
# two of its ring cover 2 × 165 = 330 s: three vehicles leave a minute of
# margin (two could not: 165 < 265). A relieved vehicle lands with about 25 %;
# if its relief never comes it leaves at 30 % and lands with about 12 %.
use Dolphin.Script

home_pos = location(40.444233, -7.375234, 820)
# The watch heights of a ring's first, second and third vehicle.
heights = [870, 885, 900]
radius = 30
# 300 m north and south of the base.
north_point = location(40.446933, -7.375234, 870)
south_point = location(40.441533, -7.375234, 870)
rounds = 3

watch = fn name, point, height ->
  mission name do
    home home_pos
    take_off location(home_pos.lat, home_pos.lon, height)
    loiter_pos location(point.lat, point.lon, height), radius
  end
end

return_home =
  mission "Return to base" do
    home home_pos
    return_home_and_land()
  end

# On station: near the point and at the watch height (a vehicle still climbing
# or already descending home is not; nor is one whose position or altitude is
# not reported yet: `near?` is then nil, which `== true` turns into false).
on_station = fn v, point, height -> near?(position(v), point, radius + 20) == true and is_number(altitude(v)) and altitude(v) >= height - 5 end

# One turn on station: until the relief `n` is there (or, with no relief
# coming, down to 30 %), then home.
shift = fn v, {n, n_height}, survey, point -> until(survey, on_station.(n, point, n_height) or battery(v) < 0.3) >>> return_home end

# The chains of one ring of vehicles watching one area: vehicle i takes off
# when vehicle i - 1 (the last one, for the first) is on station and down to
# 55 %; it stays until vehicle i + 1 (the first, for the last) is on station.
# Each vehicle with its watch height.
ring = fn vehicles, name, point ->
  vehicles = Enum.zip(vehicles, heights)
  before = [List.last(vehicles) | Enum.drop(vehicles, -1)]
  next = Enum.drop(vehicles, 1) ++ [hd(vehicles)]

  for {{{v, height}, {b, b_height}, n}, i} <- Enum.with_index(Enum.zip([vehicles, before, next])) do
    turn = shift.(v, n, watch.(name, point, height), point)
    relieve = wait_for(battery(v) >= 0.9 and on_station.(b, point, b_height) and battery(b) < 0.55, then: turn)
    # The first vehicle of the ring does not wait for anyone the first time.
    first = if i == 0, do: wait_for(battery(v) >= 0.9, then: turn), else: relieve
    {v, Enum.reduce(List.duplicate(relieve, rounds - 1), first, fn turn, chain -> chain >>> turn end)}
  end
end

north = for _ <- 1..3, do: pick(type: :uav, timeout: seconds(30))
south = for _ <- 1..3, do: pick(type: :uav, timeout: seconds(30))

execute(Map.new(ring.(north, "Watch North", north_point) ++ ring.(south, "Watch South", south_point)))
message("#{rounds} rounds of watch are over")
