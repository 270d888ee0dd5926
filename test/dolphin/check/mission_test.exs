defmodule Dolphin.Check.MissionTest do
  use ExUnit.Case, async: true

  alias Dolphin.Check.Mission, as: Check
  alias Dolphin.Mission
  alias Dolphin.Mission.Command, as: C

  @home Dolphin.Geo.location(40.0, -7.0, 100)
  @up Dolphin.Geo.location(40.0, -7.0, 130)
  @limits %{max_distance: 5_000, max_height: 200}

  # Take off 30 m, 1 km north, back and land: by the simulator's model
  # 15 s climbing at 36 A, 100 s out and 100 s back at 33 A, 20 s down at 30 A.
  defp out_and_back do
    Mission.new("Out and back", [C.home(@home), C.take_off(@up), C.move(1000, 0, 0), C.return_home_and_land()])
  end

  defp vehicle(battery, opts \\ []), do: Map.merge(%{id: 7, payloads: [], battery: battery, position: nil, airborne?: false}, Map.new(opts))

  test "length, time and battery use follow the simulator's numbers" do
    assert {[], [], e} = Check.check(out_and_back(), vehicle(1.0), @limits)
    assert_in_delta e.length_m, 2060, 1
    assert_in_delta e.time_s, 235, 0.5
    assert_in_delta e.battery_used, (36 * 15 + 33 * 200 + 30 * 20) / 3.6 / 3300, 0.001
    assert e.ending == {:landing, 3}
    assert e.lands?
  end

  test "a pack too small is an error at the item where it would be empty" do
    assert {[], [{:error, :energy, message}], _} = Check.check(out_and_back(), vehicle(0.5), @limits)
    assert message =~ "starting with 50 %: the pack would be empty at item 3 (NAV_LAND)"
  end

  test "a thin reserve once home is a warning" do
    assert {[], [{:warning, :low_reserve, message}], _} = Check.check(out_and_back(), vehicle(0.7), @limits)
    assert message =~ "5 % left once home"
  end

  test "a mission that does not come back is charged the way home" do
    away = Mission.new("Away", [C.home(@home), C.take_off(@up), C.move(1000, 0, 0)])
    assert {[], [{:error, :energy, message}], e} = Check.check(away, vehicle(0.4), @limits)
    assert message =~ "it cannot come home"
    refute e.lands?
  end

  test "a vehicle already flying needs no take-off, and starts from where it is" do
    there = Dolphin.Geo.offset(@home, 1000, 0, 30)
    back = Mission.new("Back", [C.home(@home), C.return_home_and_land()])
    assert {[], [], e} = Check.check(back, vehicle(1.0, airborne?: true, at: there), @limits)
    assert_in_delta e.length_m, 1030, 1
    assert {[{:error, :no_take_off, _}], _, _} = Check.check(Mission.new("M", [C.home(@home), C.move(10, 0, 20)]), vehicle(1.0), @limits)
    assert {[], _, _} = Check.check(Mission.new("M", [C.home(@home), C.move(10, 0, 20)]), vehicle(1.0, airborne?: true), @limits)
  end

  test "an endless mission is a note" do
    m = Mission.new("Stay", [C.home(@home), C.take_off(@up), C.move_and_loiter_pos(10, 0, 0)])
    assert {[{:note, :endless, message}], [], %{ending: {:loiter_forever, 2}}} = Check.check(m, vehicle(1.0), @limits)
    assert message =~ "flies until stopped"
  end

  test "a mission with no home to take is an error" do
    m = Mission.new("Nowhere", [C.move(10, 0, 20)])
    assert {[{:error, :mission, "mission \"Nowhere\": " <> _}], [], nil} = Check.check(m, vehicle(1.0), @limits)
  end

  test "a position off the Earth is an error" do
    m =
      Mission.new("Off", [C.home(@home), C.take_off(@up), C.item(:mav_cmd_nav_waypoint, frame: 5, x: 950_000_000, y: -70_000_000, z: 130), C.item(:mav_cmd_nav_waypoint, frame: 6, x: 0, y: 0, z: 30)])

    assert {problems, _, _} = Check.check(m, vehicle(1.0), %{max_distance: 1.0e9, max_height: 1.0e9})
    assert Enum.any?(problems, &match?({:error, :position, "mission \"Off\" on vehicle 7: item 2 (NAV_WAYPOINT) is not on Earth" <> _}, &1))
    assert Enum.any?(problems, &match?({:warning, :position, "mission \"Off\" on vehicle 7: item 3 (NAV_WAYPOINT) is at latitude 0, longitude 0" <> _}, &1))
  end

  describe "what a run would fail on, found first" do
    test "a mission with nothing to fly: no item, only a home, only settings" do
      grounded = vehicle(1.0, position: @home)
      flying = vehicle(1.0, position: @home, airborne?: true)

      for m <- [Mission.new("Empty", []), Mission.new("Home", [C.home(@home)])], v <- [grounded, flying] do
        assert {[{:error, :empty_mission, message}], [], _} = Check.check(m, v, @limits)
        assert message =~ "nothing to fly: the mission has no item after its home"
      end

      assert {[{:error, :no_take_off, message}], [], _} = Check.check(Mission.new("Speed", [C.home(@home), C.speed(5)]), grounded, @limits)
      assert message =~ ~s<mission "Speed" on vehicle 7: no take-off, and the vehicle starts on the ground: there is nothing it can fly (item 1 (DO_CHANGE_SPEED))>
      # In the air, a setting alone is a mission ArduCopter flies (and ends at once).
      assert {[], [], _} = Check.check(Mission.new("Speed", [C.home(@home), C.speed(5)]), flying, @limits)
    end

    test "a take-off from the ground to no height is an error; ArduCopter climbs 1 m, and so does the estimate" do
      for h <- [@home.h, @home.h + 0.5] do
        m = Mission.new("Low", [C.home(@home), C.take_off(%{@home | h: h}), C.move(100, 0, 0)])
        assert {[{:error, :take_off_height, message}], [], e} = Check.check(m, vehicle(1.0), @limits)
        assert message =~ "item 1 (NAV_TAKEOFF) goes to #{round(h)} m above sea level"
        assert message =~ "ArduCopter climbs only 1 m"
        assert [{_, at, true, 1} | _] = e.path
        assert_in_delta at.h, @home.h + 1, 1.0e-9
      end

      below = Mission.new("Below", [C.home(@home), C.take_off(%{@home | h: @home.h - 20}), C.move(100, 0, 0)])
      assert {problems, [], _} = Check.check(below, vehicle(1.0), @limits)
      assert Enum.sort(for {:error, kind, _} <- problems, do: kind) == [:below_ground, :below_ground, :take_off_height]

      assert {[], [], _} = Check.check(Mission.new("Up", [C.home(@home), C.take_off(%{@home | h: @home.h + 1}), C.move(100, 0, 0)]), vehicle(1.0), @limits)
      # In the air a take-off to no more height is done at once: nothing wrong.
      assert {[], [], _} = Check.check(Mission.new("Air", [C.home(@home), C.take_off(@home), C.move(100, 0, 30)]), vehicle(1.0, airborne?: true), @limits)
    end

    test "a take-off's pitch outside 0..90 degrees is an error that says where the height goes" do
      for pitch <- [860, -5, 90.5] do
        m = Mission.new("Pitch", [C.home(@home), C.take_off(@up, pitch), C.move(100, 0, 0)])
        assert {[{:error, :take_off_pitch, message}], [], _} = Check.check(m, vehicle(1.0), @limits)
        assert message =~ "item 1 (NAV_TAKEOFF) has a pitch of #{pitch}°"
        assert message =~ "its height is the location's"
      end

      for pitch <- [0, 15, 90] do
        assert {[], [], _} = Check.check(Mission.new("Pitch", [C.home(@home), C.take_off_with_yaw(@up, pitch, 90)]), vehicle(1.0), @limits)
      end
    end
  end

  describe "each airframe" do
    defp on(airframe, battery \\ 1.0), do: vehicle(battery, airframe: airframe)

    defp plane_survey(commands), do: Mission.new("Strip", [C.home(@home), C.take_off(%{@home | h: @home.h + 80}, 12)] ++ commands ++ [C.landing_point(@home)])

    test "a plane's survey whose passes are closer than it can turn is an error; slower, it turns tighter" do
      # At 22 m/s and 45° of bank a plane turns on a 49 m radius: passes 50 m apart are too close.
      assert {problems, _, _} = Check.check(plane_survey([C.survey_area(1000, 400, 50)]), on(:plane), @limits)
      assert [{:error, :turn_radius, message}] = for(p <- problems, elem(p, 0) == :error, do: p)
      assert message =~ ~s|mission "Strip" on vehicle 7: survey_area(1000, 400, 50, :north_west) puts its passes 50 m apart, and a plane at 22.0 m/s turns no tighter than a 49 m radius|
      assert message =~ "they must be at least 99 m apart"

      assert {problems, _, _} = Check.check(plane_survey([C.survey_area(1000, 400, 100)]), on(:plane), @limits)
      refute Enum.any?(problems, &match?({_, :turn_radius, _}, &1))
      # At 15 m/s the radius is 23 m.
      assert {problems, _, _} = Check.check(plane_survey([C.speed(15), C.survey_area(1000, 400, 50)]), on(:plane), @limits)
      refute Enum.any?(problems, &match?({_, :turn_radius, _}, &1))
      # A copter turns on the spot.
      copter = Mission.new("Strip", [C.home(@home), C.take_off(@up), C.survey_area(1000, 400, 20), C.return_home_and_land()])
      assert {[], _, _} = Check.check(copter, on(:copter), @limits)
    end

    test "a plane's speed below its stall speed or above its most is an error; a loiter tighter than it turns is flown wider, said as a warning" do
      assert {[{:error, :speed, slow}], _, _} = Check.check(plane_survey([C.speed(8), C.move(1000, 0, 0)]), on(:plane), @limits)
      assert slow =~ "sets 8.0 m/s, below ArduPlane's least airspeed of 10.0 m/s: it would stall"
      assert {[{:error, :speed, fast}], _, _} = Check.check(plane_survey([C.speed(35), C.move(1000, 0, 0)]), on(:plane), @limits)
      assert fast =~ "above ArduPlane's 30.0 m/s"
      # 8 m/s is a copter's business.
      assert {[], _, _} = Check.check(Mission.new("Slow", [C.home(@home), C.take_off(@up), C.speed(8), C.move(100, 0, 0)]), on(:copter), @limits)

      assert {[{:warning, :loiter_radius, wide}], _, _} = Check.check(plane_survey([C.move_and_loiter_turns(500, 0, 0, 2, 20)]), on(:plane), @limits)
      assert wide =~ "circles at a radius of 20 m: a plane flies it at about 60 m"
    end

    test "a submarine deeper than the limit is an error; the limit is the check's option" do
      dive = Mission.new("Dive", [C.home(%{@home | h: 0.0}), C.move(0, 0, -120), C.move(50, 0, 0), C.landing_point(Dolphin.Geo.location(40.0005, -7.0, 0))])
      assert {problems, _, _} = Check.check(dive, on(:sub), @limits)
      assert [{:error, :too_deep, message}, {:error, :too_deep, _}] = problems
      assert message =~ "item 1 (NAV_WAYPOINT) is 120 m deep (limit 100 m)"
      assert {[], _, _} = Check.check(dive, on(:sub), Map.put(@limits, :max_depth, 150))
    end

    test "energy and time are each airframe's: a rover draws nothing standing, a submarine the same all along, a plane circles while it holds" do
      drive = Mission.new("Drive", [C.home(@home), C.move(1000, 0, 0), C.move_and_loiter_time(0, 0, 0, 60, 0)])
      assert {[], [], rover} = Check.check(drive, on(:rover), @limits)
      # 200 s at 5 m/s and 12.4 A, then 60 s standing.
      assert_in_delta rover.time_s, 260, 0.5
      assert_in_delta rover.battery_used, 12.4 * 200 / 3.6 / 3300, 0.0005
      assert rover.hold_per_s == 0.0

      # At 1 m/s and 8 A all along a submarine goes not half as far: 1 km out is too far to come back.
      assert {[], [{:error, :energy, far}], _} = Check.check(drive, on(:sub), @limits)
      assert far =~ "it cannot come home"
      swim = Mission.new("Swim", [C.home(@home), C.move(300, 0, 0), C.move_and_loiter_time(0, 0, 0, 60, 0)])
      assert {[], [], sub} = Check.check(swim, on(:sub), @limits)
      assert_in_delta sub.time_s, 360, 0.5
      assert_in_delta sub.battery_used, 8.0 * 360 / 3.6 / 3300, 0.0005

      endless = Mission.new("Circle", [C.home(@home), C.take_off(%{@home | h: @home.h + 80}, 12), C.move_and_loiter_pos(1000, 0, 0)])
      assert {[{:note, :endless, _}], [], plane} = Check.check(endless, on(:plane), @limits)
      assert_in_delta plane.hold_per_s, 11.5 / 3.6 / 3300, 1.0e-9
      assert {[{:note, :endless, _}], [], copter} = Check.check(endless, on(:copter), @limits)
      assert_in_delta copter.hold_per_s, 30 / 3.6 / 3300, 1.0e-9
      # No note that the model is not the airframe's: every airframe has its own.
      refute Enum.any?(elem(Check.check(drive, on(:boat), @limits), 1), &match?({:note, :energy_model, _}, &1))
    end
  end
end
