# The report's Listing 4, translated faithfully: two vehicles survey; when both
# are back, the next two (picked before the first two are released, so that
# vehicles just back to charge are not picked again) take over.
#
#   mix dolphin.run examples/relay.exs --sim 4 --speedup 50
#
# Note what this really does: `execute` returns only when both vehicles have
# returned home, so one pair lands before the next pair takes off — not the
# "always two vehicles in the air" the report describes. See
# examples/relay_continuous.exs for a script that does that.
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

v1 = pick(type: :uav, timeout: seconds(30))
v2 = pick(type: :uav, timeout: seconds(30))

# The loop's state is the pair that flies next.
forever({v1, v2}, fn {v1, v2} ->
  execute %{
    v1 => wait_for(battery(v1) >= 0.9, then: until(survey_north, battery(v1) < 0.3) >>> return_home),
    v2 => wait_for(battery(v2) >= 0.9, then: until(survey_south, battery(v2) < 0.3) >>> return_home)
  }

  v1_temp = pick(type: :uav, timeout: seconds(30))
  v2_temp = pick(type: :uav, timeout: seconds(30))
  release(union(v1, v2))
  {v1_temp, v2_temp}
end)
