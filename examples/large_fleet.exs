# A thousand copters at once: each takes off 20 m above where it stands,
# climbs to 40 m, takes a photo and comes down to land where it took off,
# all at the same time.
#
#   mix dolphin.run examples/large_fleet.exs --sim 1000
#
# `--sim 1000` is four networks: vehicles 1..254 named by their system ids,
# the others `1@sim2`..`254@sim2`, `1@sim3`, ... (a network holds system
# ids 1..254). The script does not name them: it picks the whole fleet,
# waits for each to know where it is, gives each a mission of its own and
# runs them all in one `execute`. The simulator spreads the fleet 30 m
# apart in rows of ten: each staying over its own spot, no two come within
# the separation monitor's 20 m, and none is held.
#
# Shows: `pick(count: ...)` of a large fleet, a mission built per vehicle,
# `execute` of a map of a thousand tasks.
use Dolphin.Script

count = 1000

fleet = pick(type: :uav, count: count, timeout: minutes(5))

# Each vehicle's own position, once it has one (a vehicle reports where it
# is once its position estimate is ready).
execute Map.new(fleet, fn v -> {v, wait_for(position(v) != nil)} end)

hop = fn v ->
  here = position(v)

  mission "Hop" do
    take_off %{here | h: here.h + 20}
    altitude here.h + 40
    capture_photo()
    return_home_and_land()
  end
end

execute Map.new(fleet, fn v -> {v, hop.(v)} end)
message("#{Enum.count(fleet)} vehicles flew their hops")
