# The report's Listing 2: one vehicle flies a survey until its battery is below
# 30 %, returns home and lands, recharges to 90 %, and goes again — for ever.
#
#   mix dolphin.run examples/single_vehicle.exs --sim 1 --speedup 50
#
# Heights are metres above mean sea level, as in the report: home is at 820 m
# and the take-off goes to 1200 m, 380 m above the ground.
use Dolphin.Script

home_pos = location(40.444233, -7.375234, 820)
take_off_location = location(40.444233, -7.375234, 1200)

simple_mission =
  mission "Survey Area" do
    home home_pos
    take_off take_off_location
    move 100, 200, 100
    move_and_loiter_pos 200, 100, -20, 50
  end

return_home =
  mission "Return to base" do
    home home_pos
    return_home_and_land()
  end

forever do
  v1 = pick(type: :uav, timeout: seconds(30))

  execute %{
    v1 =>
      wait_for(battery(v1) >= 0.9,
        then: until(simple_mission, battery(v1) < 0.3) >>> return_home)
  }

  # Release the drone for other possible tasks.
  release(v1)
end
