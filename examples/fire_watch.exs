# Fire watch: two copters survey the two halves of an area of Serra da
# Estrela, each carrying a smoke sensor on its companion computer. Where a
# reading passes 0.4, the nearest copter not already looking breaks off its
# survey, circles the place photographing it, and goes back to its
# survey where it left it; the other flies on. The operator is told where
# (the `sensor_threshold` event and a message). As in the report's Listing 3,
# each waits for a charged battery and both go home when one runs low.
#
#   mix dolphin.run examples/fire_watch.exs --sim copter:2+smoke --world examples/worlds/serra_fire.json --speedup 20
#
# The script does not know where the fire is: the world file does (the
# simulator's smoke drifts from it with the wind). On ArduPilot SITL, a
# sensor sidecar plays the companion computers (docs/simulator.md).
#
# Shows: sensor, pick(sensors:), on_sensor, peak/3, battery handling.
use Dolphin.Script

sensor :smoke, from: {:named_value, "SMOKE"}, stale_after: seconds(5)

base = location(40.444233, -7.375234, 820)

# Each at its own height: their ways to their halves cross. No `home`: each
# mission has its vehicle's own, and each lands back on its own pad.
survey = fn name, corner ->
  mission name do
    take_off location(base.lat, base.lon, corner.h)
    survey_area corner, 250, 160, 80, :north_east
    return_home_and_land()
  end
end

west = survey.("Survey west", location(40.4455, -7.3775, 885))
east = survey.("Survey east", location(40.4455, -7.3752, 870))

# Where the smoke was read: circled once, 30 m out, photographed.
look = fn d ->
  p = d.position
  message("smoke #{Float.round(d.value, 2)} read by vehicle #{d.vehicle} at #{Float.round(p.lat, 6)}, #{Float.round(p.lon, 6)}")

  mission "Look at the smoke" do
    take_off location(p.lat, p.lon, 870)
    loiter_turns location(p.lat, p.lon, 870), 1, 30
    capture_several_photos 4, 2
  end
end

# After a look, a copter whose survey is over goes home; so do both when a battery runs low.
going_home =
  mission "Home" do
    return_home_and_land()
  end

a = pick(type: :uav, sensors: [:smoke], timeout: seconds(30))
b = pick(type: :uav, sensors: [:smoke], timeout: seconds(30))

low = fn -> battery(a) < 0.3 or battery(b) < 0.3 end

execute wait_for(battery(a) >= 0.9 and battery(b) >= 0.9,
          then: until(on_sensor(%{a => west, b => east}, :smoke, above: 0.4, apart: 150, then: look, finally: going_home), battery(a) < 0.3 or battery(b) < 0.3))

if low.() do
  message("a battery is low: both go home")
  execute(on(going_home, a) ||| on(going_home, b))
end

message("fire watch over")
release([a, b])
