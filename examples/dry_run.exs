# The engine's combinators on fake vehicles: no MAVLink, no simulator — the
# logic of a script, tried in seconds. Platform tasks here only pass time
# (Dolphin.Engine.FakePlatform); the conditions read the fake vehicles' state,
# which an action changes as a real battery would drain.
#
#   mix dolphin.run examples/dry_run.exs --fake 3 --speedup 20
use Dolphin.Script
alias Dolphin.Engine.FakePlatform
alias Dolphin.Fleet.FakeSource

# mix dolphin.run --fake names its fake source after the fleet's.
{FakeSource, fakes} = Dolphin.Fleet.source()
drain = fn v, level -> FakeSource.set(fakes, hd(Dolphin.Fleet.VehicleSet.ids(v)), battery: level) end

survey = FakePlatform.task("survey", duration: :infinity)
photos = FakePlatform.task("photos", duration: minutes(2))
return_home = FakePlatform.task("return home", duration: seconds(30))

[scout, spare] = for _ <- 1..2, do: pick(type: :uav, timeout: seconds(10))
message("scout #{inspect(scout)}, spare #{inspect(spare)}")

# The scout surveys until its battery is low (an action drains it after a
# minute), then returns; meanwhile the spare takes photos once the scout is
# airborne long enough — and everything is bounded to ten minutes.
execute during(minutes(10),
  (until(survey, battery(scout) < 0.3) >>> return_home
   |> on(scout))
  |||
  (idle(seconds(60)) >>> action do drain.(scout, 0.2) end)
  |||
  (wait_for(poll(:go), then: photos) |> on(spare))
  |||
  (idle(seconds(20)) >>> action do post(:go, true) end)
)

# one_of: whichever holds first.
execute one_of do
  battery(spare) < 0.1 -> action do message("spare is empty") end
  battery(scout) < 0.3 -> action do message("scout needs charging") end
end

# A failure handled: the fallback runs on the failed task's vehicle.
flaky = FakePlatform.task("flaky", duration: seconds(5), result: {:fail, "compass variance"})
execute watch(on(flaky, spare), on_error: fn failure ->
  message("handled: " <> Dolphin.Engine.Failure.message(failure))
  return_home
end)

release([scout, spare])
message("Done!")
