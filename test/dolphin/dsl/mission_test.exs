defmodule Dolphin.DSL.MissionTest do
  use ExUnit.Case, async: true

  import Dolphin.DSL.Mission
  import Dolphin.DSL.Values

  alias Dolphin.Mission
  alias Dolphin.Mission.Command, as: C

  doctest Dolphin.DSL.Mission

  # A function named like a command, to show that inside a block the command wins.
  defp delay(_anything), do: :not_the_mission_command

  defp kinds(%Mission{commands: commands}), do: Enum.map(commands, & &1.kind)

  defp compile_error(code) do
    assert_raise CompileError, fn -> Code.eval_string("import Dolphin.DSL.Mission\n" <> code) end
  end

  test "the report's Listing 2, translated, is the same mission as the one built with functions" do
    home_pos = location(40.444233, -7.375234, 820)
    take_off_location = location(40.444233, -7.375234, 1200)

    simple_mission =
      mission "Survey Area" do
        home home_pos
        take_off take_off_location
        move 100, 200, 100
        move_and_loiter_pos 200, 100, -20, 50
      end

    assert simple_mission ==
             Mission.new("Survey Area", [C.home(home_pos), C.take_off(take_off_location), C.move(100, 200, 100), C.move_and_loiter_pos(200, 100, -20, 50)])

    return_home =
      mission "Return to base" do
        home home_pos
        return_home_and_land()
      end

    assert return_home == Mission.new("Return to base", [C.home(home_pos), C.return_home_and_land()])
    assert length(Mission.to_items(simple_mission)) == 4
  end

  test "the report's Listing 3 missions: 42 items each" do
    home_pos = location(40.444233, -7.375234, 820)
    take_off_location = location(40.444233, -7.375234, 1200)

    survey_north =
      mission "Survey Area 1" do
        home home_pos
        take_off take_off_location
        survey_area 3000, 10000, 500, :north_east
      end

    survey_south =
      mission do
        name "Survey Area 2"
        home home_pos
        take_off take_off_location
        survey_area 3000, 10000, 500, "SOUTH_EAST"
      end

    assert survey_south.name == "Survey Area 2"
    assert Mission.item_count(survey_north) == 42
    assert Mission.item_count(survey_south) == 42
  end

  test "every Table 2 word (and the two additions) works in a block, with the parentheses of choice" do
    p = location(40.45, -7.37, 1100)

    m =
      mission "all" do
        name "All of Table 2"
        home 40.444233, -7.375234, 820
        go_pos p
        go_pos 40.45, -7.37, 1100
        take_off p
        take_off_with_yaw p, 15, 90
        move 1, 2, 3
        move_from_home 1, 2, 3
        move_and_loiter_pos 1, 2, 3
        move_and_loiter_turns 1, 2, 3, 4
        move_and_loiter_time 1, 2, 3, 60, 20
        move_and_loiter_from_home 1, 2, 3, 30
        move_and_loiter_turns_from_home 1, 2, 3, 4
        move_and_loiter_time_from_home 1, 2, 3, 60
        loiter_pos p, 20
        loiter_turns 40.45, -7.37, 1100, 2
        loiter_time p, 30
        landing_point p
        return_home()
        return_home
        return_home_and_loiter 25
        return_home_and_land
        speed 12
        altitude 900
        delay 5
        survey_area 100, 100
        survey_area p, 100, 100, 25, :south_west
        capture_photo
        capture_several_photos 3
        capture_until_stop()
        stop_capturing()
        jump_to_item 2
      end

    assert m.name == "All of Table 2"

    assert kinds(m) == [
             :go_pos,
             :go_pos,
             :take_off,
             :take_off_with_yaw,
             :move,
             :move_from_home,
             :move_and_loiter_pos,
             :move_and_loiter_turns,
             :move_and_loiter_time,
             :move_and_loiter_from_home,
             :move_and_loiter_turns_from_home,
             :move_and_loiter_time_from_home,
             :loiter_pos,
             :loiter_turns,
             :loiter_time,
             :landing_point,
             :return_home,
             :return_home,
             :return_home_and_loiter,
             :return_home_and_land,
             :speed,
             :altitude,
             :delay,
             :survey_area,
             :survey_area,
             :capture_photo,
             :capture_several_photos,
             :capture_until_stop,
             :stop_capturing,
             :jump_to_item
           ]

    assert length(Mission.to_items(m)) == 1 + 30 - 2 + 2 * 2 + 2 * 4
  end

  test "plain Elixir: variables, for, if, case, cond, Enum.map, helper functions, other missions" do
    points = for i <- 1..3, do: location(41.0 + i / 100, -8.6, 100)
    camera? = true
    leg = mission(do: move(10, 0, 0))

    m =
      mission "Tour" do
        home 41.0, -8.6, 50
        n = length(points)
        for p <- points do
          go_pos p
          if camera?, do: capture_photo()
        end

        Enum.map(points, &loiter_pos/1)
        Enum.map(points, fn p -> loiter_time(p, n) end)
        if n > 5, do: delay(1)

        case n do
          3 ->
            speed 3
            speed 4

          _ ->
            speed 1
        end

        cond do
          n < 2 -> delay(9)
          true -> [altitude(200), altitude(300)]
        end

        unless camera?, do: stop_capturing(), else: stop_capturing()
        leg
        helper_commands(2)
      end

    assert kinds(m) ==
             [:go_pos, :capture_photo, :go_pos, :capture_photo, :go_pos, :capture_photo] ++
               [:loiter_pos, :loiter_pos, :loiter_pos, :loiter_time, :loiter_time, :loiter_time] ++
               [:speed, :speed, :altitude, :altitude, :stop_capturing, :move, :delay, :delay]

    assert Enum.at(m.commands, 9).args[:time] == 3
  end

  defp helper_commands(n), do: for(_ <- 1..n, do: C.delay(1))

  test "a command word inside a block is the command, whatever else is in scope" do
    assert delay(1) == :not_the_mission_command
    m = mission(do: delay(1))
    assert m.commands == [C.delay(1)]
  end

  test "a variable named like a zero-argument command stays a variable" do
    return_home = mission(do: return_home_and_land())

    m =
      mission "uses it" do
        return_home
      end

    assert m.commands == return_home.commands
  end

  test "matches are statements; other values that are not commands are runtime errors with a hint" do
    assert mission(do: (_ = :ignored)).commands == []

    assert_raise ArgumentError, ~r/`Enum.each\(\[1\], fn _ -> delay\(1\) end\)` gave :ok, which is not a mission command.*use for/, fn ->
      mission do
        Enum.each([1], fn _ -> delay(1) end)
      end
    end
  end

  test "mistakes the macro sees are compile errors" do
    e = compile_error(~s|mission "x" do\n move 1, 2\nend|)
    assert e.description =~ "mission command move takes 3 arguments, not 2"

    e = compile_error(~s|mission "x" do\n Enum.map([1], fn _ -> delay(1); delay(2) end)\nend|)
    assert e.description =~ "the value of delay/1 is thrown away"

    e = compile_error(~s|import Dolphin.DSL.Values\nmission "x" do\n delay seconds(30)\nend|)
    assert e.description =~ "delay takes seconds as a plain number, as in the report (delay 30); seconds(...) is a duration in milliseconds"

    e = compile_error(~s|import Dolphin.DSL.Values\nmission "x" do\n loiter_time location(1, 2, 3), minutes(2)\nend|)
    assert e.description =~ "loiter_time takes seconds"
  end

  test "pipes into a command word" do
    p = location(40.45, -7.37, 1100)
    m = mission(do: p |> loiter_pos(20))
    assert m.commands == [C.loiter_pos(p, 20)]
  end

  test "a capture of a command word is the command function" do
    m = mission(do: Enum.map([3, 4], &delay/1))
    assert m.commands == [C.delay(3), C.delay(4)]
  end
end
