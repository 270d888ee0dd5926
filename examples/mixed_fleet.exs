# A mixed fleet on one coast: a plane surveys a wide strip and photographs it;
# then a copter flies low over three spots of interest in it, photographing
# each, while a boat waits at the shore until the copter has seen the last
# spot, and goes there.
#
#   mix dolphin.run examples/mixed_fleet.exs --sim plane:1,copter:1,boat:1 \
#     --home 38.43462,-8.86118 --speedup 25
#
# The plane, the copter and the boat are picked by their airframes; the
# three tasks are one composition: the survey, then the inspection and the
# boat's wait-and-go side by side (`>>>`, `|||`, `wait_for`, `on`).
use Dolphin.Script

shore = location(38.43462, -8.86118, 0)
spots = [location(38.4370, -8.8620, 0), location(38.4385, -8.8600, 0), location(38.4395, -8.8615, 0)]
last_spot = List.last(spots)

plane = pick(airframe: :plane, timeout: minutes(2))
copter = pick(airframe: :copter, timeout: minutes(2))
boat = pick(airframe: :boat, timeout: minutes(2))

# The plane: climbs out, three passes 150 m apart over the strip north of the
# shore at 80 m, photographing every 2 s, and lands back home.
wide =
  mission "Wide survey" do
    take_off location(shore.lat, shore.lon, 80)
    capture_until_stop 2
    survey_area location(38.4360, -8.8640, 80), 600, 450, 150, :north_east
    stop_capturing()
    return_home_and_land()
  end

# The copter: a photo of each spot from 25 m, then home.
inspection =
  mission "Inspection" do
    take_off location(shore.lat, shore.lon, 25)

    for s <- spots do
      [go_pos(location(s.lat, s.lon, 25)), capture_photo()]
    end

    return_home_and_land()
  end

# The boat: to the last spot, where it stays.
to_last_spot =
  mission "To the last spot" do
    go_pos last_spot
  end

execute(
  on(wide, plane) >>>
    (on(inspection, copter) |||
       wait_for(near?(position(copter), last_spot, 40), then: on(to_last_spot, boat)))
)

message("the boat is at the last spot")
release(union(union(plane, copter), boat))
