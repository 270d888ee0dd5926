# A survey that survives the loss of its vehicle: two copters survey the
# north and the south of an area while a third stands by; the north one is
# destroyed half-way (on purpose, with the simulator's fault injection) and
# the one standing by takes its survey over — a take-off where it stands,
# then the passes not flown — so the whole area is still covered, each pass
# once.
#
#   mix dolphin.run examples/resilient_survey.exs --sim 3 --speedup 25
#
# `reassign(t, from: set)` is `watch(t, on_error: :reassign, from: set)`:
# when the vehicle of a mission of `t` is lost (or fails it: a battery
# failsafe, a refused arm), the mission goes to a free vehicle of `set`.
use Dolphin.Script

home_pos = location(40.444233, -7.375234, 820)
take_off_location = location(40.444233, -7.375234, 860)

survey_north =
  mission "Survey North" do
    home home_pos
    take_off take_off_location
    survey_area 200, 300, 50, :north_east
    return_home_and_land()
  end

survey_south =
  mission "Survey South" do
    home home_pos
    take_off take_off_location
    survey_area 200, 300, 50, :south_east
    return_home_and_land()
  end

north = pick(type: :uav, timeout: seconds(30))
south = pick(type: :uav, timeout: seconds(30))
standby = pick(type: :uav, timeout: seconds(30))
team = union(union(north, south), standby)

# The fault: once the north copter has reached its 6th item (half of its
# survey's passes), its simulated autopilot is destroyed — the ground station
# stops hearing it, and after the connection timeout it is lost.
[north_id] = Dolphin.Fleet.VehicleSet.ids(north)

destroy_north =
  wait_for(mission_progress(north) >= {6, 0},
    then:
      action do
        message("destroying vehicle #{north_id} (simulator fault injection)")
        Dolphin.Sim.crash(north_id)
      end
  )

execute reassign(on(survey_north, north), from: team) ||| reassign(on(survey_south, south), from: team) ||| destroy_north

message("both surveys complete")
