defmodule Dolphin.Examples.NoFlyZoneTest do
  # examples/no_fly_zone.exs as its header says to run it: refused by the
  # pre-flight check with its line; flown anyway, stopped by the vehicle's
  # own fence at the zone, the script told why. On the built-in simulator,
  # and on ArduCopter SITL with the same history.
  # Its own Dolphin.Instance (vehicles, links, clock): its simulator runs
  # beside other tests; `make test` runs its SITL test alone (--max-cases 1).
  use ExUnit.Case, async: true

  alias Dolphin.Test.ExampleRun

  @moduletag :tmp_dir
  @moduletag timeout: 600_000

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  # As a user runs it, checked first: the check's findings, and nothing flown.
  defp refused(args) do
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    code = Mix.Tasks.Dolphin.Run.main([Path.expand("../../examples/no_fly_zone.exs", __DIR__) | args] ++ ["--no-tlog", "--quiet"], out: out, err: err)
    Dolphin.Test.GroundStation.forget_vehicles()
    {code, elem(StringIO.contents(out), 1) <> elem(StringIO.contents(err), 1)}
  end

  defp breached!(run) do
    assert run.code == 0, run.output
    [told] = for %{"event" => "message", "text" => text} <- run.events, do: text
    assert told =~ ~s(stopped at the fence: mission "North")
    assert told =~ "left AUTO for RTL"
    assert told =~ "Polygon fence breached"
    # Home again, landed.
    assert run.disarmed_at_end
    String.replace(told, ~r/\(task \d+\)/, "(task)")
  end

  test "the check refuses the mission with the line that flies it; flown anyway on the simulator, the fence stops it and the script is told", %{tmp_dir: dir} do
    {code, output} = refused(["--sim", "1", "--speedup", "25"])
    assert code == 1, output
    assert output =~ ~r/no_fly_zone\.exs:43: error: mission "North" on vehicle 1: the way to item 2 \(NAV_WAYPOINT\) enters exclusion zone 1 at 40\.44\d+, -7\.375234/

    run = ExampleRun.run(dir, "no_fly_zone", "-sim", ["--sim", "1", "--speedup", "25", "--no-check"], nil)
    breached!(run)

    # Released at the script's end, the vehicle was given back as it was found before the run closed its link:
    # the last FENCE_ENABLE it was sent is the 0 it had.
    {frames, _} = Dolphin.MAVLink.Tlog.read(Dolphin.MAVLink.Tlog.reader(), File.read!(run.tlog))
    enables = for {_, %{message: %Dolphin.MAVLink.Ardupilotmega.ParamSet{param_id: "FENCE_ENABLE", param_value: v}}} <- frames, do: v
    assert [0.0, 1.0 | _] = Enum.reverse(Enum.dedup(enables))

    # Its flight report draws the fence the vehicle was given: the circle it stays in, the no-fly zone, the rally point.
    html = Path.join(dir, "report.html")
    assert {:ok, _} = Dolphin.Report.write(run.tlog, Path.join(dir, "no_fly_zone-sim.jsonl"), html)
    page = File.read!(html)
    assert page =~ ~r/<circle class="zone inclusion" cx="[-\d.]+" cy="[-\d.]+" r="600\.0"/
    assert [_] = Regex.scan(~r/<polygon class="zone exclusion" points="[^"]+"/, page)
    assert page =~ ~s(<text class="rally")
  end

  if Dolphin.SITL.available?(:copter) do
    @tag :sitl
    test "on ArduCopter SITL: the same breach, return and words", %{tmp_dir: dir} do
      sim = ExampleRun.beside(fn -> breached!(ExampleRun.run(dir, "no_fly_zone", "-sim", ["--sim", "1", "--speedup", "10", "--no-check"], nil)) end)
      sitl = breached!(ExampleRun.run(dir, "no_fly_zone", "-sitl", ["--sitl", "1", "--speedup", "10", "--no-check"], nil))
      assert Task.await(sim, :infinity) == sitl
    end
  end
end
