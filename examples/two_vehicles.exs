# The report's Listing 3: two vehicles survey the north and the south of an
# area at the same time, each returning home when its battery falls below 30 %,
# and going again once recharged to 90 %.
#
#   mix dolphin.run examples/two_vehicles.exs --sim 2 --speedup 50
#
# `execute` gives each task its own vehicle; both run concurrently.
use Dolphin.Script

# Location of the base
home_pos = location(40.444233, -7.375234, 820)
take_off_location = location(40.444233, -7.375234, 1200)

survey_north =
  mission "Survey Area 1" do
    home home_pos
    take_off take_off_location
    survey_area 3000, 10000, 500, :north_east
  end

survey_south =
  mission "Survey Area 2" do
    home home_pos
    take_off take_off_location
    survey_area 3000, 10000, 500, :south_east
  end

return_home =
  mission "Return to base" do
    home home_pos
    return_home_and_land()
  end

forever do
  v1 = pick(type: :uav, timeout: seconds(30))
  v2 = pick(type: :uav, timeout: seconds(30))

  execute %{
    v1 => wait_for(battery(v1) >= 0.9, then: until(survey_north, battery(v1) < 0.3) >>> return_home),
    v2 => wait_for(battery(v2) >= 0.9, then: until(survey_south, battery(v2) < 0.3) >>> return_home)
  }

  release(union(v1, v2))
end
