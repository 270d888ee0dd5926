# A copter sent north across a no-fly zone, inside a fence round its base
# with a 60 m ceiling. The pre-flight check refuses the mission, with the
# line of the `execute` that would fly it and where its way enters the zone:
#
#   mix dolphin.run examples/no_fly_zone.exs --sim 1 --speedup 25
#
# Flown anyway (`--no-check`), the autopilot's own fence stops it: at the
# zone's edge it says "Polygon fence breached" and returns home (RTL); the
# mission fails with what the vehicle said, and the handler tells the
# script. (The same on ArduCopter SITL: `--sitl 1`.)
#
# Shows: `fence do ... end` (include, exclude, max_altitude, on_breach),
# `rally`, `watch` with a handler.
use Dolphin.Script

base = location(40.444233, -7.375234, 820)

fence do
  include circle(base, 600)
  # 80 to 120 m north of the base, 100 m wide.
  exclude polygon([
            Dolphin.Geo.offset(base, 80, -50),
            Dolphin.Geo.offset(base, 80, 50),
            Dolphin.Geo.offset(base, 120, 50),
            Dolphin.Geo.offset(base, 120, -50)
          ])
  max_altitude 60
  on_breach :rtl
end

rally [Dolphin.Geo.offset(base, 0, 60, 30)]

north =
  mission "North" do
    home base
    take_off location(40.444233, -7.375234, 840)
    move 200, 0, 0
    return_home_and_land()
  end

v = pick(type: :uav, region: area(base, meters(200)), timeout: minutes(1))

execute %{
  v =>
    watch(north,
      on_error: fn failure ->
        message("stopped at the fence: " <> Dolphin.Engine.Failure.message(failure))
      end
    )
}
