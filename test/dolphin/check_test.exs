defmodule Dolphin.CheckTest do
  # Not async: a test looks at the default instance's events, vehicles and
  # fleet, at the dry runs' instances being gone, and one keeps both cores busy.
  use ExUnit.Case

  alias Dolphin.Check
  alias Dolphin.Check.{FleetFile, FleetFileError}

  doctest Dolphin.Check.Finding
  doctest Dolphin.Check.FleetFile
  doctest Dolphin.Check.FleetFileError

  @dir "test/fixtures/check"

  setup_all do
    {:ok, fleet} = FleetFile.read(Path.join(@dir, "fleet.json"))
    %{fleet: fleet}
  end

  defp check(name, fleet, opts \\ []), do: Check.run(Path.join(@dir, name), [fleet: fleet] ++ opts)
  defp kinds(report, severity \\ :error), do: for(f <- report.findings, f.severity == severity, uniq: true, do: f.kind)
  defp finding(report, kind), do: Enum.find(report.findings, &(&1.kind == kind))

  test "a sound script has no error, and its mission is estimated", %{fleet: fleet} do
    report = check("ok.exs", fleet)
    refute Check.errors?(report), Check.format(report)
    assert [%{mission: "Hop", length_m: length, time_s: time, battery_used: used, line: 14}] = report.missions
    assert length > 200 and time > 20 and used > 0 and used < 0.2
    assert Check.format(report) =~ "0 error(s)"
  end

  test "what a run would fail on or never end is an error, with the line that flies it: nothing to fly, a take-off to no height, a pitch for a height", %{fleet: fleet} do
    report = check("cannot_fly.exs", fleet)
    errors = for f <- report.findings, f.severity == :error, do: {f.line, f.kind, f.message}

    assert [{26, :empty_mission, empty}, {27, :empty_mission, _}, {28, :no_take_off, speed}, {29, :take_off_pitch, pitch}, {29, :take_off_height, height}] = errors
    assert empty =~ ~s(mission "Empty" on vehicle 211: nothing to fly: the mission has no item after its home)
    assert speed =~ "no take-off, and the vehicle starts on the ground: there is nothing it can fly"
    assert pitch =~ "item 1 (NAV_TAKEOFF) has a pitch of 860°"
    assert height =~ "item 1 (NAV_TAKEOFF) goes to 820 m above sea level, 0 m above the ground the vehicle takes off from (820 m): ArduCopter climbs only 1 m"
    # The estimate is ArduCopter's flight: 1 m up, then at the ground's height.
    assert %{length_m: length} = List.last(report.missions)
    assert length < 205
  end

  test "the fence: a leg into a no-fly zone, out of the fence or over its ceiling is an error with the line; a mission's own fence that home is outside of too", %{fleet: fleet} do
    report = check("fenced.exs", fleet)
    errors = for f <- report.findings, f.kind == :fence, do: {f.line, f.message}

    assert [{41, through}, {41, out}, {42, high}, {58, elsewhere}] = errors
    assert through =~ ~r/^mission "Through the zone" on vehicle 211: the way to item 2 \(NAV_WAYPOINT\) enters exclusion zone 1 at 40\.44\d+, -7\.375234$/
    assert out =~ "the way to item 3 (NAV_LAND) leaves inclusion zone 1 at"
    assert high =~ ~s|mission "Too high" on vehicle 211: item 2 (NAV_WAYPOINT) is 140 m above home, over the fence's max_altitude of 120 m|
    assert elsewhere =~ ~s|mission "Elsewhere" on vehicle 211: the fence's inclusion zone 1 (#Circle<|
    assert elsewhere =~ "does not contain home"
    # Round the zone, inside the square, under the ceiling: nothing to say.
    refute Enum.any?(report.findings, &(&1.line == 43 and &1.kind == :fence))
  end

  test "two of our vehicles on crossing ways at once: an error with when and where, at the line that flies them; a script's own least separation", _ do
    {:ok, fleet} = FleetFile.read(Path.join(@dir, "crossing_fleet.json"))
    report = check("crossing.exs", fleet)
    assert [%{severity: :error, line: 23, message: message}] = Enum.filter(report.findings, &(&1.kind == :separation))
    assert message =~ ~r/^vehicles 211 and 212 come within \d m of each other across and 0 m in height 4\d s into the run, at 40\.4442\d+, -7\.3752\d+ /
    assert message =~ ~s|(mission "East" on vehicle 211 and mission "North" on vehicle 212); the least separation is 20 m across or 10 m in height|

    # In a run on simulated vehicles, which pass through each other, a warning.
    report = check("crossing.exs", fleet, separation: :warning)
    assert [%{severity: :warning}] = Enum.filter(report.findings, &(&1.kind == :separation))

    # Ten metres higher, one passes over the other: apart.
    source = File.read!(Path.join(@dir, "crossing.exs")) |> String.replace("Dolphin.Geo.offset(base, -300, 0, 30)", "Dolphin.Geo.offset(base, -300, 0, 42)")
    over = Path.join(System.tmp_dir!(), "crossing_over_#{System.unique_integer([:positive])}.exs")
    File.write!(over, source)
    on_exit(fn -> File.rm(over) end)
    assert [] = Enum.filter(Check.run(over, fleet: fleet).findings, &(&1.kind == :separation))
    # 34 m apart at their closest: too close for a script that keeps 40 m.
    File.write!(over, String.replace(source, "base = location", "min_separation 40, 15\nbase = location"))
    assert [%{message: wider}] = Enum.filter(Check.run(over, fleet: fleet).findings, &(&1.kind == :separation))
    assert wider =~ "the least separation is 40 m across or 15 m in height"
  end

  # examples/two_vehicles.exs (`make run`): two surveys that share their
  # first leg and part at its end, each stopped by its battery part way
  # along a 3 km leg, then both home to land at one point. Placed at the
  # last corner each had reached, the two stood together there until
  # stopped and flew home as one: the check's one conflict was at that
  # corner, and the landing it had hidden is what `make run` showed (the
  # second copter let down onto the first, parked).
  test "flights stopped part way along a leg are placed there: two surveys that part, then land at one point together" do
    report = Check.run("examples/two_vehicles.exs", sim: 2)
    assert [%{line: 38, message: message}] = Enum.filter(report.findings, &(&1.kind == :separation))
    assert message =~ ~r/^vehicles 1 and 2 come within 0 m of each other across and 0 m in height 10\.\d min into the run, at 40\.444233, -7\.375234 /
    assert message =~ ~s|(mission "Return to base" on vehicle 1 and mission "Return to base" on vehicle 2)|
    # Home from a kilometre or so out along each survey's second leg, not from its first corner (630 m).
    assert [_, _] = returns = for(%{mission: "Return to base", length_m: length} <- report.missions, do: length)
    assert Enum.all?(returns, &(&1 > 1_000)), inspect(returns)
  end

  test "a script that does not compile is an error with its line", %{fleet: fleet} do
    report = check("unknown_word.exs", fleet)
    assert %{severity: :error, line: 3, message: message} = finding(report, :compile)
    assert message =~ "pik/1"
  end

  test "every kind of mission fault is found, with the script line", %{fleet: fleet} do
    report = check("bad_mission.exs", fleet, max_distance: 5_000, max_height: 300)
    assert Enum.sort(kinds(report)) -- [:allocation, :script, :energy] == Enum.sort([:below_ground, :too_far, :too_high, :no_take_off, :loiter_radius, :speed])
    assert finding(report, :below_ground).line == 18
    assert finding(report, :too_far).message =~ "limit 5000 m"
  end

  test "photos on a vehicle without a camera are an error" do
    home = Dolphin.Geo.location(40.0, -7.0, 100)
    mission = Dolphin.Mission.new("P", [Dolphin.Mission.Command.home(home), Dolphin.Mission.Command.take_off(%{home | h: 130}), Dolphin.Mission.Command.capture_photo()])
    vehicle = %{id: 5, payloads: [], battery: 1.0, position: nil, airborne?: false}
    assert {[{:error, :no_camera, message}], _energy, %{}} = Dolphin.Check.Mission.check(mission, vehicle, %{max_distance: 1000, max_height: 100})
    assert message =~ "vehicle 5 has no camera"
  end

  test "a jump to a missing item is an error" do
    mission = Dolphin.Mission.new("J", [Dolphin.Mission.Command.home(Dolphin.Geo.location(40.0, -7.0, 100)), Dolphin.Mission.Command.jump_to_item(9)])
    vehicle = %{id: 1, payloads: [], battery: 1.0, position: nil, airborne?: true}
    assert {[{:error, :jump, message}], [], nil} = Dolphin.Check.Mission.check(mission, vehicle, %{max_distance: 1000, max_height: 100})
    assert message =~ "9"
  end

  test "a pick nothing can serve is an error that says which and why", %{fleet: fleet} do
    report = check("no_pick.exs", fleet, horizon_ms: 600_000)
    assert %{severity: :error, line: 3, message: message} = finding(report, :pick)
    assert message =~ "thermal_camera"
  end

  test "a composition with more tasks than vehicles cannot be allocated", %{fleet: fleet} do
    report = check("too_few.exs", fleet)
    assert Check.errors?(report)
    assert Enum.any?(report.findings, &(&1.kind in [:allocation, :script] and &1.line == 12)), Check.format(report)
  end

  test "a mission the pack cannot fly is reported with the item where it would be empty", %{fleet: fleet} do
    fleet = Enum.map(fleet, &%{&1 | battery: 0.5})
    report = check("low_battery.exs", fleet)
    assert %{severity: :error, line: 15, message: message} = finding(report, :energy)
    assert message =~ "starting with 50 %"
    assert message =~ ~r/empty at item \d|cannot come home/
  end

  test "a flight cut short before the pack runs out is no error; one that runs it out before its stop is", %{fleet: fleet} do
    # The script flies for about an hour of the dry run's clock: a horizon of
    # six hours lets it end.
    report = check("cut_short.exs", fleet, horizon_ms: 6 * 3_600_000)
    assert [%{mission: "Long", battery_start: 1.0}, %{mission: "Back", battery_start: back}, %{mission: "Long"} | _] = report.missions
    # The stop came on the condition.
    assert back < 0.6
    assert [%{line: 23, message: message}] = Enum.filter(report.findings, &(&1.kind == :energy))
    assert message =~ "the pack would be empty after"
    assert message =~ "before anything stopped it"
  end

  test "a dry run is nobody else's: no event, view or pick of it reaches the caller's instance", %{fleet: fleet} do
    Dolphin.Test.Instance.start!()
    Dolphin.Events.subscribe()
    report = check("ok.exs", fleet)
    assert [%{mission: "Hop"}] = report.missions
    refute_received {:dolphin, :events, _}
    assert Dolphin.Vehicles.list() == []
    assert Dolphin.Fleet.vehicles() == []
    for slot <- 1..4, do: refute(Dolphin.Instance.running?(Module.concat(Dolphin.Check.DryRun, "#{slot}")))
  end

  # Each dry run's clock moves once its own processes wait: neither another
  # dry run nor a process that never waits (here two, one per core) holds
  # it up or makes it move early.
  @tag timeout: 600_000
  test "dry runs side by side, on a VM kept busy by something else, find what each finds alone", %{fleet: fleet} do
    {:ok, crossing} = FleetFile.read(Path.join(@dir, "crossing_fleet.json"))
    runs = [fn -> Check.run("examples/photo_patrol.exs", sim: 3) end, fn -> check("crossing.exs", crossing) end, fn -> check("cut_short.exs", fleet, horizon_ms: 6 * 3_600_000) end]
    shown = fn report -> {Check.format(report), report.missions} end
    alone = Enum.map(runs, &shown.(&1.()))

    busy = for _ <- 1..2, do: spawn(fn -> Stream.repeatedly(fn -> :erlang.phash2(make_ref()) end) |> Stream.run() end)

    try do
      together = runs |> Enum.map(&Task.async(fn -> shown.(&1.()) end)) |> Task.await_many(:infinity)

      for {a, t} <- Enum.zip(alone, together) do
        assert t == a, "alone:\n#{elem(a, 0)}\nside by side, busy VM:\n#{elem(t, 0)}"
      end
    after
      Enum.each(busy, &Process.exit(&1, :kill))
    end
  end

  test "a mixed fleet: a boat's heights are warned about, a submarine's depths are no error, a take-off on a boat is refused with the line" do
    {:ok, fleet} = FleetFile.read(Path.join(@dir, "mixed_fleet.json"))
    report = check("mixed_fleet.exs", fleet)
    assert [%{mission: "Patrol", vehicle: 31}, %{mission: "Dive", vehicle: 32}] = Enum.sort_by(report.missions, & &1.vehicle)
    # The move up and the return over home at the height it left.
    assert [%{severity: :warning, line: 23, message: ignored}, %{line: 23}] = Enum.filter(report.findings, &(&1.kind == :height_ignored))
    assert ignored =~ ~s|mission "Patrol" on vehicle 31: item 2 (NAV_WAYPOINT) is 30 m above home: a boat drives at its own height|
    refute Enum.any?(report.findings, &(&1.kind in [:below_ground, :no_take_off]))
    assert %{severity: :error, line: 31, message: refused} = Enum.find(report.findings, &(&1.severity == :error))
    assert refused =~ "no vehicle matches airframe [:copter, :plane, :quadplane]"
    assert refused =~ "31 (usv boat)"
  end

  test "a condition never met with the fleet's values is a note, not an error", %{fleet: fleet} do
    fleet = Enum.map(fleet, &%{&1 | battery: 0.5})
    report = check("waits.exs", fleet, horizon_ms: 600_000)
    refute Check.errors?(report)
    assert %{severity: :note, line: 4} = finding(report, :waiting)
  end

  test "a loop in which nothing waits is an error naming the loop's line, not the note of a script still waiting", %{fleet: fleet} do
    report = check("busy_loop.exs", fleet, horizon_ms: 600_000)
    assert [%{severity: :error, kind: :busy_loop, line: 7, message: message}] = report.findings
    assert message =~ "nothing in this `forever` loop waits"
    # A loop that waits is a script still running at the horizon: a note, no error.
    report = check("waits.exs", Enum.map(fleet, &%{&1 | battery: 0.5}), horizon_ms: 600_000)
    assert [%{severity: :note, kind: :waiting}] = report.findings
  end

  test "a question to the operator is a note with its line", %{fleet: fleet} do
    report = check("asks.exs", fleet)
    refute Check.errors?(report)
    assert %{severity: :note, line: 3, message: message} = finding(report, :ask)
    assert message =~ ~S|asks "Fly the survey? (y/n)"|
  end

  test "what a script does with an answer the dry run could not give is a note, not an error", %{fleet: fleet} do
    report = check("asks_then_uses.exs", fleet)
    refute Check.errors?(report)
    assert %{severity: :note, line: 4, message: message} = finding(report, :script)
    assert message =~ "after an `ask` the dry run could not answer"
  end

  test "the JSON form names each finding", %{fleet: fleet} do
    map = "bad_mission.exs" |> check(fleet) |> Check.to_map()
    json = :jiffy.decode(:jiffy.encode(map), [:return_maps])
    assert json["ok"] == false
    assert Enum.any?(json["findings"], &(&1["kind"] == "no_take_off" and &1["line"] == 18 and &1["severity"] == "error"))
  end

  describe "fleet files" do
    test "bad ones say what is wrong and where" do
      assert {:error, %FleetFileError{message: "vehicle #1: \"position\" is missing" <> _}} = FleetFile.parse(~s({"vehicles":[{"id":1}]}))
      # A run takes only payloads from the file: a vehicle needs no position there (null is none), but one given must be a position.
      assert {:ok, [%{id: 1, payloads: [:sonar], position: nil}]} = FleetFile.parse(~s({"vehicles":[{"id":1,"payloads":["sonar"]}]}), position: :optional)
      assert {:ok, [%{id: 1, position: nil}]} = FleetFile.parse(~s({"vehicles":[{"id":1,"position":null}]}), position: :optional)
      assert {:error, %FleetFileError{message: "vehicle #1: \"position\" must be" <> _}} = FleetFile.parse(~s({"vehicles":[{"id":1,"position":[1,2]}]}), position: :optional)
      assert {:error, %FleetFileError{message: "vehicle #1: \"position\" must be" <> _}} = FleetFile.parse(~s({"vehicles":[{"id":1,"position":null}]}))
      assert {:error, %FleetFileError{message: "vehicle #2: id 1 is given twice"}} = FleetFile.parse(~s({"vehicles":[{"id":1,"position":[1,2,3]},{"id":1,"position":[1,2,3]}]}))
      assert {:error, %FleetFileError{message: "not valid JSON" <> _}} = FleetFile.parse("{")
      assert {:error, %FleetFileError{message: "vehicle #1: \"battery\" must be" <> _}} = FleetFile.parse(~s({"vehicles":[{"id":1,"battery":2,"position":[1,2,3]}]}))

      assert {:error, %FleetFileError{message: "vehicle #1: unknown type \"submarine_zz\" (one of uav, ugv, usv, uuv, other)"}} =
               FleetFile.parse(~s({"vehicles":[{"id":1,"type":"submarine_zz","position":[1,2,3]}]}))
    end

    test "every type a pick names, no type, and any payload name are read" do
      text = ~s({"vehicles": [
        {"id": 1, "type": "uav", "payloads": ["camera", "lidar_x9_never_named"], "position": [40.44, -7.37, 820]},
        {"id": 2, "type": "ugv", "position": [40.44, -7.37, 820]},
        {"id": 3, "type": "usv", "position": [40.44, -7.37, 820]},
        {"id": 4, "type": "uuv", "position": [40.44, -7.37, 820]},
        {"id": 5, "type": "other", "position": [40.44, -7.37, 820]},
        {"id": 6, "position": [40.44, -7.37, 820], "battery": 0, "airborne": true}]})

      assert {:ok, vehicles} = FleetFile.parse(text)
      assert Enum.map(vehicles, & &1.type) == [:uav, :ugv, :usv, :uuv, :other, :uav]
      assert hd(vehicles).payloads == [:camera, :lidar_x9_never_named]
      assert %{battery: 0.0, airborne?: true} = List.last(vehicles)
    end

    test "every problem of every vehicle is reported, not only the first" do
      text = ~s({"vehicles": [
        {"id": 1, "type": "boat", "battery": 2, "position": [40.44, -7.37, 820]},
        {"id": 300, "payloads": ["Thermal Camera"]},
        {"id": 1, "position": [40.44, -7.37, 820], "airborne": "no"},
        {"id": 1, "position": [40.44, -7.37, 820]}]})

      assert {:error, %FleetFileError{problems: problems} = e} = FleetFile.parse(text)

      assert problems == [
               ~s<vehicle #1: unknown type "boat" (one of uav, ugv, usv, uuv, other)>,
               ~s<vehicle #1: "battery" must be a number from 0.0 to 1.0, got 2>,
               ~s<vehicle #2: "id" must be an integer system id 0..255, got 300>,
               ~s<vehicle #2: payload names are lower-case letters, digits and _ (as in "thermal_camera"), got "Thermal Camera">,
               ~s<vehicle #2: "position" is missing ([latitude, longitude, height above sea level], latitude -90..90, longitude -180..180)>,
               ~s<vehicle #3: "airborne" must be true or false, got "no">,
               "vehicle #3: id 1 is given twice",
               "vehicle #4: id 1 is given twice"
             ]

      assert Exception.message(%{e | file: "f.json"}) =~ ~r/^fleet file f.json: 8 problems:\n  vehicle #1: unknown type "boat"/
    end

    test "text that is not JSON is described in the file's terms: what, byte, line" do
      assert {:error, e} = FleetFile.parse(~s({"vehicles": [\n  {"id": 1,\n))
      assert e.message == "not valid JSON: the text ends in the middle of a value (byte 27, line 3, column 1)"

      assert {:error, e} = FleetFile.parse(~s({"vehicles": [\n  {"id": 1 "position": [1, 2, 3]}]}))
      assert e.message == ~s|not valid JSON: expected , or } in an object, found "\\"position\\": " (byte 26, line 2, column 12)|

      assert {:error, %FleetFileError{message: "not valid JSON: the file is empty"}} = FleetFile.parse("  \n")
    end
  end
end
