defmodule Dolphin.Console.MissionSourceTest do
  use ExUnit.Case, async: true

  import Dolphin.DSL.Mission
  import Dolphin.DSL.Values

  alias Dolphin.Console.MissionSource
  alias Dolphin.Mission

  defp eval(source, binding \\ []) do
    {mission, _} =
      Code.eval_string("import Dolphin.DSL.Mission; import Dolphin.DSL.Values; " <> source, binding)

    mission
  end

  test "every command's source gives the mission back exactly" do
    h = location(40.444233, -7.375234, 820)

    m =
      mission "All \"the\" words" do
        home h
        go_pos location(40.4443, -7.3753, 850.5)
        take_off location(40.444233, -7.375234, 1200)
        take_off_with_yaw location(40.444233, -7.375234, 1200), 10, 90
        take_off_with_yaw 40.1, -7.2, 900, 10
        move 100, 200, 100
        move_from_home 10, 20.5, 30
        move_and_loiter_pos 200, 100, -20, 50
        move_and_loiter_turns 1, 2, 3, 4
        move_and_loiter_time 1, 2, 3, 40, 20
        move_and_loiter_from_home 1, 2, 3
        move_and_loiter_turns_from_home 1, 2, 3, 5, 25
        move_and_loiter_time_from_home 1, 2, 3, 5
        loiter_pos h
        loiter_turns h, 3
        loiter_time h, 30, 12
        landing_point h
        landing_point h, 45
        landing_point h, 45, 2
        return_home()
        return_home_and_loiter 30
        return_home_and_land()
        return_home_and_land 90, 1
        speed 12
        speed 3, :climb_speed
        altitude 900
        delay 30
        survey_area 300, 100, 50, :north_east
        survey_area h, 300, 100
        capture_photo()
        capture_several_photos 10, 2
        capture_until_stop 3
        stop_capturing()
        jump_to_item 2, 3
        item :mav_cmd_do_set_servo, params: [1, 1500, 0, 0]
        item 16, params: [0, 0, 0, :nan], frame: 6, x: 404442330, y: -73752340, z: 20.0
        item 16, position: h, autocontinue: 0
      end

    source = MissionSource.to_source(m)
    assert source =~ ~r/^mission "All \\"the\\" words" do\n  home location\(40.444233, -7.375234, 820.0\)\n/
    assert source =~ "\n  take_off location(40.444233, -7.375234, 1200.0), 15\n"
    assert source =~ "\n  return_home()\n"
    assert source =~ "\n  survey_area 300, 100, 50, :north_east\n"
    assert source =~ "\n  item :mav_cmd_do_set_servo, params: [1.0, 1500.0, 0.0, 0.0], frame: 2, x: 0, y: 0, z: 0.0\n"
    assert String.ends_with?(source, "autocontinue: 0\nend")
    assert eval(source) == m
  end

  test "a mission without a home" do
    m = mission("No home", do: go_pos(location(40.1, -7.2, 900)))
    assert MissionSource.to_source(m) == "mission \"No home\" do\n  go_pos location(40.1, -7.2, 900.0)\nend"
    assert eval(MissionSource.to_source(m)) == m
  end

  test "downloaded items become the mission that gives them back" do
    h = location(40.444233, -7.375234, 820)

    m =
      mission "Down" do
        home h
        take_off location(40.444233, -7.375234, 850)
        move_and_loiter_time 50, 0, 0, 10
        speed 5
        capture_photo()
        return_home_and_land()
      end

    items = Mission.to_items(m)
    # As ArduPilot gives them back: frames without _INT.
    downloaded = Enum.map(items, fn i -> if i.frame == 5, do: %{i | frame: 0}, else: i end)
    assert {:ok, back} = MissionSource.from_items(downloaded, "vehicle 1")
    assert back.name == "vehicle 1"
    assert Enum.map(Mission.to_items(back), &Map.drop(&1, [:seq])) == Enum.map(items, &Map.drop(&1, [:seq]))
    assert {:error, _} = MissionSource.from_items([], "x")
  end
end
