# Two copters sent across each other's way at the same moment: the west
# one flies north-east, the east one north-west, and their diagonals cross
# 250 m north of the base at the same height, when both are there.
#
#   mix dolphin.run examples/crossing_paths.exs --sim 2 --speedup 10
#
# The pre-flight check (`mix dolphin.check examples/crossing_paths.exs
# --sim 2`) refuses it: the two come within the least separation (20 m
# across, 10 m in height), with when and where, at the line of the
# `execute`. On simulated vehicles `mix dolphin.run` shows that as a
# warning and flies, and the live separation monitor keeps them apart: a
# few seconds before the crossing it holds the vehicle whose task started
# later (`separation_hold`), lets the other pass, and sends it on once the
# way is clear (`separation_clear`); both missions end done. (The same on
# ArduCopter SITL: `--sitl 2`.)
#
# Shows: `execute` of two missions at once, `pick` by region, the
# separation monitor.
use Dolphin.Script

base = location(40.444233, -7.375234, 820)
at = fn north, east, up -> Dolphin.Geo.offset(base, north, east, up) end

# The simulator and SITL stand two vehicles 30 m apart, east and west of the base.
west_pad = area(at.(0, -15, 0), meters(10))
east_pad = area(at.(0, 15, 0), meters(10))

north_east =
  mission "North-east" do
    take_off at.(0, 0, 30)
    go_pos at.(100, -150, 30)
    go_pos at.(400, 150, 30)
    landing_point at.(400, 150, 0)
  end

north_west =
  mission "North-west" do
    take_off at.(0, 0, 30)
    go_pos at.(100, 150, 30)
    go_pos at.(400, -150, 30)
    landing_point at.(400, -150, 0)
  end

west = pick(type: :uav, region: west_pad, timeout: minutes(1))
east = pick(type: :uav, region: east_pad, timeout: minutes(1))

execute %{west => north_east, east => north_west}
