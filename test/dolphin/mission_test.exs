defmodule Dolphin.MissionTest do
  use ExUnit.Case, async: true

  alias Dolphin.Geo
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.Frame
  alias Dolphin.Mission
  alias Dolphin.Mission.Command, as: C

  doctest Dolphin.Mission
  doctest Dolphin.Mission.Command
  doctest Dolphin.Mission.PlanError
  doctest Dolphin.Mission.MismatchError

  @home Geo.location(40.444233, -7.375234, 820)
  @up Geo.location(40.444233, -7.375234, 1200)
  @p Geo.location(40.45, -7.37, 1100)

  # Frames and commands by their names in the dialect, not by number.
  defp frame(name), do: elem(M.enum_value(:mav_frame, name), 1)
  defp cmd(name), do: elem(M.enum_value(:mav_cmd, name), 1)

  # The items a command gives, after home and a take-off to 1200 m.
  defp items(commands) do
    Mission.new("t", [C.home(@home), C.take_off(@up) | List.wrap(commands)]) |> Mission.to_items() |> Enum.drop(2)
  end

  defp item(command) do
    [item] = items(command)
    item
  end

  defp params(item), do: [item.param1, item.param2, item.param3, item.param4]
  defp e7(deg), do: round(deg * 1.0e7)
  defp at(item), do: {item.x, item.y, item.z}
  defp xyz(%Geo.Location{} = p), do: {e7(p.lat), e7(p.lon), p.h}

  defp global?(item), do: item.frame == frame(:mav_frame_global_int)
  defp mission_frame?(item), do: item.frame == frame(:mav_frame_mission) and {item.x, item.y, item.z} == {0, 0, 0.0}

  describe "every item" do
    test "is numbered from 0 (home), autocontinue 1, current 0, mission list, and encodes as MISSION_ITEM_INT" do
      m =
        Mission.new("all", [
          C.home(@home),
          C.take_off(@up),
          C.speed(12),
          C.move(100, 200, 100),
          C.survey_area(300, 200, 50, :south_east),
          C.capture_photo(),
          C.delay(3),
          C.jump_to_item(3, 2),
          C.return_home_and_land()
        ])

      items = Mission.to_items(m)
      assert Enum.map(items, & &1.seq) == Enum.to_list(0..(length(items) - 1))
      assert length(items) == 1 + 1 + 1 + 1 + 8 + 1 + 1 + 1 + 1

      for item <- items do
        assert %M.MissionItemInt{autocontinue: 1, current: 0, mission_type: 0, target_system: 0, target_component: 0} = item
        assert item.frame in [frame(:mav_frame_global_int), frame(:mav_frame_mission)]
        {:ok, decoded, ""} = item |> Frame.encode() |> Frame.decode(M)
        assert Map.take(decoded.message, [:seq, :command, :frame, :x, :y]) == Map.take(item, [:seq, :command, :frame, :x, :y])
      end
    end

    test "item 0 is home: a waypoint at home, absolute height" do
      [home | _] = Mission.to_items(Mission.new("h", [C.home(@home)]))
      assert home.seq == 0
      assert home.command == cmd(:mav_cmd_nav_waypoint)
      assert global?(home)
      assert at(home) == {404_442_330, -73_752_340, 820.0}
      assert params(home) == [0.0, 0.0, 0.0, 0.0]
    end
  end

  describe "Table 2, command by command" do
    test "name sets the name; it adds no item" do
      m = Mission.new("first", [C.home(@home), C.name("Survey Area")])
      assert m.name == "Survey Area"
      assert m.commands == []
      assert length(Mission.to_items(m)) == 1
    end

    test "home, as a location or lat, lon, h" do
      assert Mission.new("a", C.home(40.444233, -7.375234, 820)).home == @home
      assert Mission.new("a", C.home(@home)).home == @home
    end

    test "go_pos: NAV_WAYPOINT at the position, hold 0, yaw NaN" do
      for command <- [C.go_pos(@p), C.go_pos(40.45, -7.37, 1100)] do
        i = item(command)
        assert i.command == cmd(:mav_cmd_nav_waypoint)
        assert global?(i)
        assert at(i) == {404_500_000, -73_700_000, 1100.0}
        assert params(i) == [0.0, 0.0, 0.0, :nan]
      end
    end

    test "take_off: NAV_TAKEOFF at the position, pitch default 15, yaw NaN" do
      [_home, t] = Mission.to_items(Mission.new("t", [C.home(@home), C.take_off(@up)]))
      assert t.command == cmd(:mav_cmd_nav_takeoff)
      assert global?(t)
      assert at(t) == {404_442_330, -73_752_340, 1200.0}
      assert params(t) == [15.0, 0.0, 0.0, :nan]

      assert params(item(C.take_off(@p, 10))) == [10.0, 0.0, 0.0, :nan]
      assert params(item(C.take_off(40.45, -7.37, 1100))) == [15.0, 0.0, 0.0, :nan]
      assert item(C.take_off(40.45, -7.37, 1100, 5)) == item(C.take_off(@p, 5))
    end

    test "take_off_with_yaw: position, pitch, yaw (default NaN)" do
      assert params(item(C.take_off_with_yaw(@p, 12, 90))) == [12.0, 0.0, 0.0, 90.0]
      assert params(item(C.take_off_with_yaw(@p, 12))) == [12.0, 0.0, 0.0, :nan]
      assert item(C.take_off_with_yaw(40.45, -7.37, 1100, 12, 45)) == item(C.take_off_with_yaw(@p, 12, 45))
      assert item(C.take_off_with_yaw(@p, 12)).command == cmd(:mav_cmd_nav_takeoff)
    end

    test "move: NAV_WAYPOINT north, east, up of the previous point" do
      [a, b] = items([C.move(100, 200, 100), C.move(-50, 0, -300)])
      pa = Geo.offset(@up, 100, 200, 100)
      pb = Geo.offset(pa, -50, 0, -300)
      assert a.command == cmd(:mav_cmd_nav_waypoint) and global?(a)
      assert at(a) == xyz(pa)
      assert at(b) == xyz(pb)
      assert b.z == 1000.0
      assert params(a) == [0.0, 0.0, 0.0, :nan]
    end

    test "move_from_home: relative to home, whatever came before" do
      [_, b] = items([C.move(1000, 0, 0), C.move_from_home(100, 200, 400)])
      assert at(b) == xyz(Geo.offset(@home, 100, 200, 400))
      assert b.z == 1220.0
      assert b.command == cmd(:mav_cmd_nav_waypoint)
    end

    test "move_and_loiter_pos: NAV_LOITER_UNLIM, radius in param 3 (default 15)" do
      i = item(C.move_and_loiter_pos(200, 100, -20, 50))
      assert i.command == cmd(:mav_cmd_nav_loiter_unlim)
      assert at(i) == xyz(Geo.offset(@up, 200, 100, -20))
      assert params(i) == [0.0, 0.0, 50.0, 0.0]
      assert params(item(C.move_and_loiter_pos(200, 100, -20))) == [0.0, 0.0, 15.0, 0.0]
    end

    test "move_and_loiter_turns: NAV_LOITER_TURNS, turns in param 1, radius in param 3" do
      i = item(C.move_and_loiter_turns(10, 20, 30, 3, 40))
      assert i.command == cmd(:mav_cmd_nav_loiter_turns)
      assert at(i) == xyz(Geo.offset(@up, 10, 20, 30))
      assert params(i) == [3.0, 0.0, 40.0, 0.0]
      assert params(item(C.move_and_loiter_turns(10, 20, 30, 3))) == [3.0, 0.0, 15.0, 0.0]
    end

    test "move_and_loiter_time: NAV_LOITER_TIME, seconds in param 1, radius in param 3" do
      i = item(C.move_and_loiter_time(10, 20, 30, 60, 25))
      assert i.command == cmd(:mav_cmd_nav_loiter_time)
      assert at(i) == xyz(Geo.offset(@up, 10, 20, 30))
      assert params(i) == [60.0, 0.0, 25.0, 0.0]
      assert params(item(C.move_and_loiter_time(10, 20, 30, 60))) == [60.0, 0.0, 15.0, 0.0]
    end

    test "the _from_home loiters: from home" do
      [_, a, b, c] =
        items([
          C.move(5000, 5000, 0),
          C.move_and_loiter_from_home(10, 20, 30),
          C.move_and_loiter_turns_from_home(10, 20, 30, 2),
          C.move_and_loiter_time_from_home(10, 20, 30, 9, 33)
        ])

      where = xyz(Geo.offset(@home, 10, 20, 30))
      assert {a.command, at(a), params(a)} == {cmd(:mav_cmd_nav_loiter_unlim), where, [0.0, 0.0, 15.0, 0.0]}
      assert {b.command, at(b), params(b)} == {cmd(:mav_cmd_nav_loiter_turns), where, [2.0, 0.0, 15.0, 0.0]}
      assert {c.command, at(c), params(c)} == {cmd(:mav_cmd_nav_loiter_time), where, [9.0, 0.0, 33.0, 0.0]}
    end

    test "loiter_pos, loiter_turns, loiter_time: at the position, as a location or lat, lon, h" do
      assert item(C.loiter_pos(@p)) == item(C.loiter_pos(40.45, -7.37, 1100))
      assert item(C.loiter_pos(@p, 30)) == item(C.loiter_pos(40.45, -7.37, 1100, 30))
      i = item(C.loiter_pos(@p))
      assert {i.command, at(i), params(i)} == {cmd(:mav_cmd_nav_loiter_unlim), xyz(@p), [0.0, 0.0, 15.0, 0.0]}

      assert item(C.loiter_turns(@p, 4)) == item(C.loiter_turns(40.45, -7.37, 1100, 4))
      i = item(C.loiter_turns(@p, 4, -20))
      assert {i.command, at(i), params(i)} == {cmd(:mav_cmd_nav_loiter_turns), xyz(@p), [4.0, 0.0, -20.0, 0.0]}
      assert params(item(C.loiter_turns(@p, 4))) == [4.0, 0.0, 15.0, 0.0]

      assert item(C.loiter_time(@p, 45, 20)) == item(C.loiter_time(40.45, -7.37, 1100, 45, 20))
      i = item(C.loiter_time(@p, 45))
      assert {i.command, at(i), params(i)} == {cmd(:mav_cmd_nav_loiter_time), xyz(@p), [45.0, 0.0, 15.0, 0.0]}
    end

    test "landing_point: NAV_LAND, land mode in param 2 (default 0), yaw in param 4 (default NaN)" do
      i = item(C.landing_point(@p))
      assert {i.command, at(i), params(i)} == {cmd(:mav_cmd_nav_land), xyz(@p), [0.0, 0.0, 0.0, :nan]}
      assert params(item(C.landing_point(@p, 90))) == [0.0, 0.0, 0.0, 90.0]
      assert params(item(C.landing_point(@p, 90, 2))) == [0.0, 2.0, 0.0, 90.0]
      assert params(item(C.landing_point(@p, :nan, :opportunistic))) == [0.0, 1.0, 0.0, :nan]
      assert item(C.landing_point(40.45, -7.37, 1100)) == item(C.landing_point(@p))
      assert item(C.landing_point(40.45, -7.37, 1100, 10)) == item(C.landing_point(@p, 10))
      assert item(C.landing_point(40.45, -7.37, 1100, 10, 1)) == item(C.landing_point(@p, 10, 1))
    end

    test "return_home: a waypoint over home at the previous height" do
      [_, i] = items([C.move(300, 300, 50), C.return_home()])
      assert {i.command, at(i), params(i)} == {cmd(:mav_cmd_nav_waypoint), {404_442_330, -73_752_340, 1250.0}, [0.0, 0.0, 0.0, :nan]}
    end

    test "return_home_and_loiter: a loiter over home at the previous height, radius default 15" do
      [_, i] = items([C.move(300, 300, 50), C.return_home_and_loiter()])
      assert {i.command, at(i), params(i)} == {cmd(:mav_cmd_nav_loiter_unlim), {404_442_330, -73_752_340, 1250.0}, [0.0, 0.0, 15.0, 0.0]}
      assert params(item(C.return_home_and_loiter(40))) == [0.0, 0.0, 40.0, 0.0]
    end

    test "return_home_and_land: NAV_LAND at home (home's height), yaw NaN and land mode 0 by default" do
      i = item(C.return_home_and_land())
      assert {i.command, at(i), params(i)} == {cmd(:mav_cmd_nav_land), {404_442_330, -73_752_340, 820.0}, [0.0, 0.0, 0.0, :nan]}
      assert params(item(C.return_home_and_land(180))) == [0.0, 0.0, 0.0, 180.0]
      assert params(item(C.return_home_and_land(180, :required))) == [0.0, 2.0, 0.0, 180.0]
    end

    test "speed: DO_CHANGE_SPEED, speed type in param 1 (default 0, airspeed), speed in param 2, throttle unchanged" do
      i = item(C.speed(12.5))
      assert i.command == cmd(:mav_cmd_do_change_speed)
      assert mission_frame?(i)
      assert params(i) == [0.0, 12.5, -1.0, 0.0]
      assert params(item(C.speed(3, 2))) == [2.0, 3.0, -1.0, 0.0]
      assert params(item(C.speed(3, :ground_speed))) == [1.0, 3.0, -1.0, 0.0]
      assert params(item(C.speed(3, :descent_speed))) == [3.0, 3.0, -1.0, 0.0]
    end

    test "altitude: a waypoint over the previous point at the new height (metres AMSL)" do
      [a, b] = items([C.move(100, 0, 0), C.altitude(1500)])
      assert {b.x, b.y} == {a.x, a.y}
      assert b.z == 1500.0
      assert b.command == cmd(:mav_cmd_nav_waypoint)
      # ... and it is the previous point for what follows
      [_, _, c] = items([C.move(100, 0, 0), C.altitude(1500), C.move(0, 0, 10)])
      assert c.z == 1510.0
    end

    test "delay: NAV_DELAY, seconds in param 1, no time of day" do
      i = item(C.delay(30))
      assert i.command == cmd(:mav_cmd_nav_delay)
      assert mission_frame?(i)
      assert params(i) == [30.0, -1.0, -1.0, -1.0]
    end

    test "survey_area: two waypoints per pass from the previous point; defaults spacing 50, :north_west" do
      survey = items(C.survey_area(300, 220))
      # ceil(220 / 50) = 5 passes
      assert length(survey) == 10
      assert Enum.all?(survey, &(&1.command == cmd(:mav_cmd_nav_waypoint) and global?(&1) and &1.z == 1200.0))
      expected = Dolphin.Mission.Survey.waypoints(@up, 300, 220, 50, :north_west) |> Enum.map(&xyz/1)
      assert Enum.map(survey, &at/1) == expected
      [first | _] = survey
      {n, e} = Geo.ne_offset(@up, Geo.location(first.x / 1.0e7, first.y / 1.0e7))
      # north west: the first pass is 22 m west of the base, starting on its parallel
      assert_in_delta n, 0.0, 0.02
      assert_in_delta e, -22.0, 0.02
    end

    test "survey_area: the other forms (spacing, direction, a base position, lat/lon/h, the report's strings)" do
      assert length(items(C.survey_area(300, 220, 100))) == 6
      assert items(C.survey_area(300, 220, 100, :south_east)) == items(C.survey_area(@up, 300, 220, 100, :south_east))
      assert items(C.survey_area(300, 220, 100, "SOUTH_EAST")) == items(C.survey_area(300, 220, 100, :south_east))
      assert items(C.survey_area(@p, 300, 220)) == items(C.survey_area(40.45, -7.37, 1100, 300, 220))
      assert items(C.survey_area(@p, 300, 220, 70)) == items(C.survey_area(40.45, -7.37, 1100, 300, 220, 70))
      assert items(C.survey_area(@p, 300, 220, 70, :north_east)) == items(C.survey_area(40.45, -7.37, 1100, 300, 220, 70, :north_east))
      assert items(C.survey_area(@p, 300, 220)) == items(C.survey_area(@p, 300, 220, 50, :north_west))
      assert Enum.all?(items(C.survey_area(@p, 300, 220)), &(&1.z == 1100.0))
    end

    test "survey_area: the end of the survey is the previous point of what follows" do
      survey = items([C.survey_area(300, 220), C.move(0, 0, 0)])
      [last_of_survey, moved] = Enum.take(survey, -2)
      assert at(moved) == at(last_of_survey)
    end

    test "capture_photo: IMAGE_START_CAPTURE of one image, all cameras, numbered 1, 2, ..." do
      [a, b] = items([C.capture_photo(), C.capture_photo()])
      assert a.command == cmd(:mav_cmd_image_start_capture)
      assert mission_frame?(a)
      assert params(a) == [0.0, 0.0, 1.0, 1.0]
      assert params(b) == [0.0, 0.0, 1.0, 2.0]
    end

    test "capture_several_photos: IMAGE_START_CAPTURE, interval (default 2 s) in param 2, count in param 3" do
      i = item(C.capture_several_photos(10, 5))
      assert {i.command, params(i)} == {cmd(:mav_cmd_image_start_capture), [0.0, 5.0, 10.0, 0.0]}
      assert mission_frame?(i)
      assert params(item(C.capture_several_photos(10))) == [0.0, 2.0, 10.0, 0.0]
    end

    test "capture_until_stop: IMAGE_START_CAPTURE, 0 images (until stopped), interval default 2 s" do
      assert params(item(C.capture_until_stop())) == [0.0, 2.0, 0.0, 0.0]
      i = item(C.capture_until_stop(4))
      assert {i.command, params(i)} == {cmd(:mav_cmd_image_start_capture), [0.0, 4.0, 0.0, 0.0]}
    end

    test "stop_capturing: IMAGE_STOP_CAPTURE, all cameras, no NaN (ArduPilot refuses it there)" do
      i = item(C.stop_capturing())
      assert {i.command, params(i)} == {cmd(:mav_cmd_image_stop_capture), [0.0, 0.0, 0.0, 0.0]}
      assert mission_frame?(i)
    end

    test "jump_to_item: DO_JUMP to a seq, repeat default 1, -1 for ever" do
      [_, i] = items([C.move(1, 1, 1), C.jump_to_item(2)])
      assert {i.command, params(i)} == {cmd(:mav_cmd_do_jump), [2.0, 1.0, 0.0, 0.0]}
      assert mission_frame?(i)
      [_, i] = items([C.move(1, 1, 1), C.jump_to_item(2, :forever)])
      assert params(i) == [2.0, -1.0, 0.0, 0.0]
      [_, i] = items([C.move(1, 1, 1), C.jump_to_item(1, 5)])
      assert params(i) == [1.0, 5.0, 0.0, 0.0]
    end

    test "item: any other MAV_CMD as given" do
      i = item(C.item(:mav_cmd_do_set_servo, params: [9, 1500, 0, 0]))
      assert {i.command, params(i)} == {cmd(:mav_cmd_do_set_servo), [9.0, 1500.0, 0.0, 0.0]}
      assert mission_frame?(i)
      i = item(C.item(201, params: [3, 0, 0, 0], position: @p))
      assert {i.command, i.frame, at(i)} == {201, 5, xyz(@p)}
      i = item(C.item(16, frame: 6, x: 1, y: 2, z: 30, autocontinue: 0))
      assert {i.frame, i.x, i.y, i.z, i.autocontinue} == {6, 1, 2, 30.0, 0}
    end
  end

  describe "the report's listings" do
    test "Listing 2: home, take-off, two relative moves; the return mission is one landing" do
      survey = Mission.new("Survey Area", [C.home(@home), C.take_off(@up), C.move(100, 200, 100), C.move_and_loiter_pos(200, 100, -20, 50)])
      items = Mission.to_items(survey)
      assert Enum.map(items, & &1.command) == [16, 22, 16, 17]
      # Coordinates of GeographicLib's direct problem (see test/dolphin/geo_test.exs).
      assert Enum.map(items, &at/1) == [
               {404_442_330, -73_752_340, 820.0},
               {404_442_330, -73_752_340, 1200.0},
               {404_451_335, -73_728_765, 1300.0},
               {404_469_346, -73_716_978, 1280.0}
             ]

      back = Mission.new("Return to base", [C.home(@home), C.return_home_and_land()])
      assert [_, %{command: 21, x: 404_442_330, y: -73_752_340, z: 820.0}] = Mission.to_items(back)
    end

    test "Listing 3: a 3 km × 10 km survey with 500 m passes is home, take-off and 40 waypoints" do
      north = Mission.new("Survey Area 1", [C.home(@home), C.take_off(@up), C.survey_area(3000, 10000, 500, "NORTH_EAST")])
      south = Mission.new("Survey Area 2", [C.home(@home), C.take_off(@up), C.survey_area(3000, 10000, 500, "SOUTH_EAST")])
      assert Mission.item_count(north) == 42
      assert Mission.item_count(south) == 42
      # North and east (south and east) of the base, in its north/east metres.
      ne = fn item -> Geo.ne_offset(@up, Geo.location(item.x / 1.0e7, item.y / 1.0e7)) end
      assert Enum.all?(Enum.drop(Mission.to_items(north), 2), fn i -> {n, e} = ne.(i); n > -0.02 and e > 0 end)
      assert Enum.all?(Enum.drop(Mission.to_items(south), 2), fn i -> {n, e} = ne.(i); n < 0.02 and e > 0 end)
    end
  end

  describe "building" do
    test "add takes commands, nested lists, nils and other missions' commands" do
      leg = Mission.new("leg", [C.move(1, 0, 0), C.move(0, 1, 0)])
      m = Mission.new("m") |> Mission.add([C.home(@home), [nil, [leg]], C.delay(1)])
      assert Enum.map(m.commands, & &1.kind) == [:move, :move, :delay]
      assert m.home == @home
    end

    test "a mission without home takes its first absolute position; to_items(home: ...) supplies one" do
      m = Mission.new("no home", [C.move(10, 0, 0), C.take_off(@up), C.go_pos(@p)])
      [home | _] = Mission.to_items(m)
      assert at(home) == xyz(@up)

      [home, moved | _] = Mission.to_items(m, home: @home)
      assert at(home) == xyz(@home)
      assert at(moved) == xyz(Geo.offset(@home, 10, 0, 0))
    end

    test "the same mission at another home moves with it" do
      m = Mission.new("shape", [C.home(@home), C.move(100, 0, 0)])
      elsewhere = Geo.location(41.0, -8.0, 10)
      [_, a] = Mission.to_items(Mission.put_home(m, elsewhere))
      assert at(a) == xyz(Geo.offset(elsewhere, 100, 0, 0))
      assert Mission.put_name(m, "other").name == "other"
    end

    test "mistakes are ArgumentErrors naming the value" do
      assert_raise ArgumentError, ~r/no home/, fn -> Mission.to_items(Mission.new("x", [C.move(1, 2, 3)])) end
      assert_raise ArgumentError, ~r/already has a home/, fn -> Mission.new("x", [C.home(@home), C.home(@p)]) end
      assert_raise ArgumentError, ~r/not a mission command: :ok/, fn -> Mission.new("x", [:ok]) end
      assert_raise ArgumentError, ~r/name is a string, got: :x/, fn -> Mission.new(:x) end

      assert_raise ArgumentError, ~r/item 2 jumps to item 9, which does not exist \(items run from 1 to 2\)/, fn ->
        Mission.to_items(Mission.new("x", [C.home(@home), C.move(1, 1, 1), C.jump_to_item(9)]))
      end

      assert_raise ArgumentError, ~r/move: east must be a number, got: "2"/, fn -> C.move(1, "2", 3) end
      assert_raise ArgumentError, ~r/go_pos: latitude must be within -90..90 degrees, got: 100/, fn -> C.go_pos(100, 0, 0) end
      assert_raise ArgumentError, ~r/take_off: expected a location .* got: \{1, 2, 3\}/, fn -> C.take_off({1, 2, 3}) end
      assert_raise ArgumentError, ~r/take_off: a position is a location or lat, lon, h; got only 1, 2/, fn -> C.take_off(1, 2) end
      assert_raise ArgumentError, ~r/loiter_turns: turns must be a non-negative number, got: -1/, fn -> C.loiter_turns(@p, -1) end
      assert_raise ArgumentError, ~r/delay: seconds must be a non-negative number of seconds, got: -5/, fn -> C.delay(-5) end
      assert_raise ArgumentError, ~r/landing_point: the land mode is .* got: 7/, fn -> C.landing_point(@p, 0, 7) end
      assert_raise ArgumentError, ~r/yaw must be a number of degrees or :nan, got: "north"/, fn -> C.landing_point(@p, "north") end
      assert_raise ArgumentError, ~r/speed: the speed type is .* got: :warp/, fn -> C.speed(3, :warp) end
      assert_raise ArgumentError, ~r/survey_area: the direction is .* got: :up/, fn -> C.survey_area(1, 1, 1, :up) end
      assert_raise ArgumentError, ~r/survey_area: the direction .* got: "NORTH"/, fn -> C.survey_area(1, 1, 1, "NORTH") end
      assert_raise ArgumentError, ~r/survey_area: spacing must be a positive number of metres, got: 0/, fn -> C.survey_area(1, 1, 0) end
      assert_raise ArgumentError, ~r/photo count must be a positive integer, got: 0/, fn -> C.capture_several_photos(0) end
      assert_raise ArgumentError, ~r/interval must be a positive number of seconds, got: 0/, fn -> C.capture_until_stop(0) end
      assert_raise ArgumentError, ~r/jump_to_item: the target .* got: 0/, fn -> C.jump_to_item(0) end
      assert_raise ArgumentError, ~r/jump_to_item: repeat .* got: :sometimes/, fn -> C.jump_to_item(1, :sometimes) end
      assert_raise ArgumentError, ~r/unknown MAV_CMD :mav_cmd_teleport/, fn -> C.item(:mav_cmd_teleport) end
      assert_raise ArgumentError, ~r/params are four numbers/, fn -> C.item(16, params: [1]) end
      assert_raise ArgumentError, ~r/name is a string, got: 42/, fn -> C.name(42) end
    end
  end

  describe "property" do
    import Dolphin.Property

    # float32 rounding, as the wire carries params and z
    defp f32(:nan), do: :nan

    defp f32(x) do
      <<y::float-32>> = <<x::float-32>>
      y
    end

    test "any mission of relative moves, loiters, surveys and settings gives contiguous items that go over the wire unchanged" do
      coord = :proper_types.float(-20_000.0, 20_000.0)

      command =
        :proper_types.oneof([
          :proper_types.tuple([:move, coord, coord, :proper_types.float(-300.0, 300.0)]),
          :proper_types.tuple([:from_home, coord, coord, :proper_types.float(-300.0, 300.0)]),
          :proper_types.tuple([:turns, coord, coord, :proper_types.integer(0, 255), :proper_types.float(-255.0, 255.0)]),
          :proper_types.tuple([:survey, :proper_types.float(1.0, 5000.0), :proper_types.float(1.0, 5000.0), :proper_types.float(50.0, 1000.0)]),
          :proper_types.tuple([:speed, :proper_types.float(0.1, 40.0)]),
          :proper_types.tuple([:altitude, :proper_types.float(0.0, 4000.0)]),
          :proper_types.tuple([:home_and_land])
        ])

      check(
        forall(:proper_types.list(command), fn spec ->
          commands =
            Enum.map(spec, fn
              {:move, n, e, u} -> C.move(n, e, u)
              {:from_home, n, e, u} -> C.move_from_home(n, e, u)
              {:turns, n, e, t, r} -> C.move_and_loiter_turns(n, e, 0, t, r)
              {:survey, l, w, s} -> C.survey_area(l, w, s, :north_west)
              {:speed, v} -> C.speed(v, 1)
              {:altitude, h} -> C.altitude(h)
              {:home_and_land} -> C.return_home_and_land()
            end)

          items = Mission.to_items(Mission.new("p", [C.home(@home) | commands]))
          assert Enum.map(items, & &1.seq) == Enum.to_list(0..(length(items) - 1))

          for item <- items do
            {:ok, %{message: back}, ""} = item |> Frame.encode() |> Frame.decode(M)
            assert Map.take(back, [:seq, :command, :frame, :x, :y, :autocontinue]) == Map.take(item, [:seq, :command, :frame, :x, :y, :autocontinue])
            assert [back.param1, back.param2, back.param3, back.param4, back.z] == Enum.map([item.param1, item.param2, item.param3, item.param4, item.z], &f32/1)
          end
        end),
        numtests: 100
      )
    end
  end

  describe "ending" do
    test "landing, loitering for ever, looping for ever, or reaching the last navigation item" do
      base = [C.home(@home), C.take_off(@up)]
      assert Mission.ending(Mission.new("a", base ++ [C.move(1, 1, 1), C.return_home_and_land(), C.capture_photo()])) == {:landing, 3}
      assert Mission.ending(Mission.new("b", base ++ [C.landing_point(@p)])) == {:landing, 2}
      assert Mission.ending(Mission.new("c", base ++ [C.item(:mav_cmd_nav_return_to_launch)])) == {:landing, 2}
      assert Mission.ending(Mission.new("d", base ++ [C.loiter_pos(@p), C.speed(3)])) == {:loiter_forever, 2}
      assert Mission.ending(Mission.new("e", base ++ [C.move(1, 1, 1), C.jump_to_item(2, :forever), C.landing_point(@p)])) == {:loops_forever, 3}
      assert Mission.ending(Mission.new("f", base ++ [C.move(1, 1, 1), C.jump_to_item(2, 3)])) == {:reached, 2}
      assert Mission.ending(Mission.new("g", base ++ [C.loiter_time(@p, 10), C.delay(4), C.stop_capturing()])) == {:reached, 3}
      assert Mission.ending(Mission.new("h", [C.home(@home), C.speed(3)])) == {:reached, 0}
    end
  end

  describe "compare_download" do
    setup do
      m = Mission.new("m", [C.home(@home), C.take_off(@up), C.speed(5), C.move(100, 200, 100), C.move_and_loiter_time(10, 0, 0, 30, 40)])
      %{up: Mission.to_items(m)}
    end

    # What ArduPilot sends back: its own home, non-_INT frames, items without a
    # position in frame 0, heights from centimetres in float32, params dropped.
    defp as_downloaded(items) do
      Enum.map(items, fn item ->
        <<z::float-32>> = <<item.z::float-32>>
        %{item | frame: 0, z: z, param4: 0.0, param3: if(item.command == 19, do: 1.0, else: item.param3)}
      end)
      |> List.replace_at(0, %M.MissionItemInt{seq: 0, command: 16, x: 404_442_331, y: -73_752_339, z: 821.5})
    end

    test "what ArduPilot gives back matches", %{up: up} do
      assert Mission.compare_download(up, as_downloaded(up)) == :ok
      assert Mission.compare_download(up, up) == :ok
    end

    test "a missing item, another command, another position, height or altitude reference do not", %{up: up} do
      down = as_downloaded(up)
      assert "the vehicle has 4 items, 5 were uploaded" = mismatch(Mission.compare_download(up, Enum.drop(down, -1)))
      assert "item 2 is command 177 on the vehicle, 178 was uploaded" = mismatch(Mission.compare_download(up, List.update_at(down, 2, &%{&1 | command: 177})))
      assert "item 3 is at " <> _ = mismatch(Mission.compare_download(up, List.update_at(down, 3, &%{&1 | x: &1.x + 1})))
      assert "item 4 is at height " <> _ = mismatch(Mission.compare_download(up, List.update_at(down, 4, &%{&1 | z: &1.z + 0.5})))
      assert "item 1 has frame 3 on the vehicle, 5 was uploaded" = mismatch(Mission.compare_download(up, List.update_at(down, 1, &%{&1 | frame: 3})))
    end
  end

  describe "inspect" do
    test "a mission shows its name and one line per item" do
      m = Mission.new("Survey Area", [C.home(@home), C.take_off(@up), C.speed(12), C.move(100, 200, 100)])

      assert inspect(m) == """
             #Dolphin.Mission<"Survey Area", 4 items:
                0 home                 40.4442330, -7.3752340, 820 m  [0, 0, 0, 0]
                1 NAV_TAKEOFF          40.4442330, -7.3752340, 1200 m  [15, 0, 0, NaN]
                2 DO_CHANGE_SPEED      [0, 12, -1, 0]
                3 NAV_WAYPOINT         40.4451335, -7.3728765, 1300 m  [0, 0, 0, NaN]
             >\
             """
    end

    test "a mission that cannot be turned into items shows why and its commands" do
      assert inspect(Mission.new("x", [C.move(1, 2, 3)])) =~ ~r/^#Dolphin.Mission<"x", mission "x" has no home.*commands: \[move\(1, 2, 3\)\]>$/
    end

    test "commands show as they are written" do
      assert inspect(C.survey_area(3000, 10000, 500, :north_east)) == "survey_area(3000, 10000, 500, :north_east)"
      assert inspect(C.landing_point(Geo.location(40.5, -7.25, 800.5))) == "landing_point(location(40.5, -7.25, 800.5), :nan, 0)"
    end
  end

  defp mismatch(result) do
    assert {:error, %Dolphin.Mission.MismatchError{} = e} = result
    Exception.message(e)
  end
end
