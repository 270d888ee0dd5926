# What the report's Listing 4 wanted: two areas watched all the time. Each area
# has a relay of vehicles; a replacement takes off when the vehicle on station
# falls to 60 % — in time to climb to the survey height — and the vehicle on
# station flies home at 30 %, so the area is never left without a vehicle.
#
#   mix dolphin.run examples/relay_continuous.exs --sim 6 --speedup 50
#
# The relay of an area is a ring: each vehicle waits for the one before it to
# be flying low on battery (and for its own battery to be charged), surveys,
# returns, recharges, and waits for its turn again. The first vehicle of each
# ring starts at once. Everything runs in one `execute`, each vehicle with its
# own chain of tasks.
use Dolphin.Script

home_pos = location(40.444233, -7.375234, 820)
take_off_location = location(40.444233, -7.375234, 1200)
rounds = 2

survey_north =
  mission "Watch North" do
    home home_pos
    take_off take_off_location
    survey_area 3000, 10000, 500, :north_east
  end

survey_south =
  mission "Watch South" do
    home home_pos
    take_off take_off_location
    survey_area 3000, 10000, 500, :south_east
  end

return_home =
  mission "Return to base" do
    home home_pos
    return_home_and_land()
  end

# One turn on station: until 30 %, then home.
shift = fn v, survey -> until(survey, battery(v) < 0.3) >>> return_home end

# The chains of one ring of vehicles watching one area: vehicle i takes off
# when vehicle i - 1 (the last one, for the first) is flying and down to 60 %.
ring = fn vehicles, survey ->
  before = [List.last(vehicles) | Enum.drop(vehicles, -1)]

  for {{v, b}, i} <- Enum.with_index(Enum.zip(vehicles, before)) do
    relieve = wait_for(battery(v) >= 0.9 and armed?(b) and battery(b) < 0.6, then: shift.(v, survey))
    # The first vehicle of the ring does not wait for anyone the first time.
    first = if i == 0, do: wait_for(battery(v) >= 0.9, then: shift.(v, survey)), else: relieve
    {v, Enum.reduce(List.duplicate(relieve, rounds - 1), first, fn turn, chain -> chain >>> turn end)}
  end
end

north = for _ <- 1..3, do: pick(type: :uav, timeout: seconds(30))
south = for _ <- 1..3, do: pick(type: :uav, timeout: seconds(30))

execute(Map.new(ring.(north, survey_north) ++ ring.(south, survey_south)))
message("#{rounds} rounds of watch are over")
