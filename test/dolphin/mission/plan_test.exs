defmodule Dolphin.Mission.PlanTest do
  use ExUnit.Case, async: true

  import Dolphin.Property

  alias Dolphin.Geo
  alias Dolphin.Mission
  alias Dolphin.Mission.Command, as: C
  alias Dolphin.Mission.PlanError

  doctest Dolphin.Mission.Plan

  # Written by hand in QGroundControl's format (keys sorted, 4-space indents,
  # integers where QGroundControl writes them): absolute items in frame 0 with
  # AltitudeMode 2, one item relative to home (frame 3, AltitudeMode 1),
  # commands without a position in frame 2 without altitude keys.
  @fixture Path.expand("../../fixtures/plans/serra_da_estrela.plan", __DIR__)

  @home Geo.location(40.444233, -7.375234, 820)

  defp json(text), do: :jiffy.decode(text, [:return_maps])

  # Numbers compared as floats: QGroundControl writes 15 where we write 15.0.
  defp normalize(%{} = map), do: Map.new(map, fn {k, v} -> {k, normalize(v)} end)
  defp normalize(list) when is_list(list), do: Enum.map(list, &normalize/1)
  defp normalize(n) when is_number(n), do: n / 1
  defp normalize(other), do: other

  test "a QGroundControl plan is read into the commands that give its items back" do
    mission = Mission.from_plan!(File.read!(@fixture), name: "Serra da Estrela")
    assert mission.name == "Serra da Estrela"
    assert mission.home == @home

    assert Enum.map(mission.commands, & &1.kind) == [
             :take_off,
             :speed,
             :go_pos,
             # a waypoint with a hold time: no Table 2 command makes it
             :item,
             :capture_until_stop,
             :loiter_turns,
             :stop_capturing,
             :delay,
             # relative to home: kept as is
             :item,
             :jump_to_item,
             :loiter_time,
             :capture_photo,
             # DO_SET_SERVO
             :item,
             :landing_point
           ]

    assert Enum.at(mission.commands, 1) == C.speed(12.0, 1)
    assert Enum.at(mission.commands, 9) == C.jump_to_item(3, 2)
    assert Enum.at(mission.commands, 5) == C.loiter_turns(Geo.location(40.4469346, -7.3716978, 1280), 3.0, 40.0)

    items = Mission.to_items(mission)
    assert length(items) == 15
    assert Enum.map(items, & &1.frame) == [5, 5, 2, 5, 5, 2, 5, 2, 2, 6, 2, 5, 2, 2, 5]
    relative = Enum.at(items, 9)
    assert {relative.command, relative.x, relative.y, relative.z} == {16, 404_470_000, -73_740_000, 100.0}
    hold = Enum.at(items, 4)
    assert {hold.param1, hold.param4, hold.x, hold.z} == {5.0, :nan, 404_460_000, 1300.0}
  end

  test "the plan is written back with the same items, home and header" do
    original = json(File.read!(@fixture))
    exported = File.read!(@fixture) |> Mission.from_plan!() |> Mission.to_plan() |> json()

    assert normalize(exported["mission"]["items"]) == normalize(original["mission"]["items"])
    assert normalize(exported["mission"]["plannedHomePosition"]) == normalize(original["mission"]["plannedHomePosition"])

    for key <- ["version", "firmwareType", "vehicleType", "cruiseSpeed", "hoverSpeed", "globalPlanAltitudeMode"] do
      assert exported["mission"][key] == original["mission"][key], key
    end

    for key <- ["fileType", "version", "geoFence", "rallyPoints"], do: assert(exported[key] == original[key], key)
    assert exported["groundStation"] == "Dolphin"
  end

  test "a mission's plan: QGroundControl's frames and altitude modes, NaN as null, doJumpId = seq" do
    m =
      Mission.new("Survey Area", [
        C.home(@home),
        C.take_off(40.444233, -7.375234, 1200),
        C.speed(10, :ground_speed),
        C.move(100, 200, 100),
        C.jump_to_item(3, 1)
      ])

    plan = json(Mission.to_plan(m, cruise_speed: 12, hover_speed: 4))
    mission = plan["mission"]
    assert {mission["cruiseSpeed"], mission["hoverSpeed"], mission["firmwareType"], mission["vehicleType"]} == {12, 4, 3, 2}
    assert mission["plannedHomePosition"] == [40.444233, -7.375234, 820.0]
    assert mission["globalPlanAltitudeMode"] == 2
    [take_off, speed, move, jump] = mission["items"]

    assert take_off == %{
             "type" => "SimpleItem",
             "autoContinue" => true,
             "command" => 22,
             "doJumpId" => 1,
             "frame" => 0,
             "params" => [15.0, 0.0, 0.0, :null, 40.444233, -7.375234, 1200.0],
             "AltitudeMode" => 2,
             "Altitude" => 1200.0,
             "AMSLAltAboveTerrain" => :null
           }

    assert speed == %{"type" => "SimpleItem", "autoContinue" => true, "command" => 178, "doJumpId" => 2, "frame" => 2, "params" => [1.0, 10.0, -1.0, 0.0, 0, 0, 0.0]}
    assert move["doJumpId"] == 3 and move["command"] == 16
    assert jump["params"] |> Enum.take(2) == [3.0, 1.0]
  end

  test "a jump names its target by doJumpId in the plan, by seq in the mission" do
    plan = json(File.read!(@fixture))
    # Renumber the doJumpIds as another tool might: 101, 102, ...; the jump targets the third item.
    items =
      plan["mission"]["items"]
      |> Enum.with_index(1)
      |> Enum.map(fn {item, i} ->
        item = Map.put(item, "doJumpId", 100 + i)
        if item["command"] == 177, do: put_in(item, ["params"], List.replace_at(item["params"], 0, 103)), else: item
      end)

    mission = Mission.from_plan!(put_in(plan, ["mission", "items"], items))
    assert Enum.at(mission.commands, 9) == C.jump_to_item(3, 2)
  end

  test "from_plan(to_plan(m)) gives m's items back, for random missions" do
    command =
      :proper_types.oneof([
        :proper_types.tuple([:move, :proper_types.float(-5000.0, 5000.0), :proper_types.float(-5000.0, 5000.0), :proper_types.float(-100.0, 100.0)]),
        :proper_types.tuple([:loiter, :proper_types.float(-5000.0, 5000.0), :proper_types.float(1.0, 200.0), :proper_types.integer(0, 20)]),
        :proper_types.tuple([:survey, :proper_types.float(10.0, 2000.0), :proper_types.float(10.0, 2000.0), :proper_types.float(50.0, 500.0)]),
        :proper_types.tuple([:speed, :proper_types.float(0.5, 30.0), :proper_types.integer(0, 3)]),
        :proper_types.tuple([:delay, :proper_types.integer(0, 600)]),
        :proper_types.tuple([:photo, :proper_types.integer(0, 20)]),
        :proper_types.tuple([:land, :proper_types.oneof([:nan, :proper_types.float(0.0, 359.0)]), :proper_types.integer(0, 2)]),
        :proper_types.tuple([:servo, :proper_types.integer(1, 16), :proper_types.integer(1000, 2000)])
      ])

    check(
      forall(:proper_types.list(command), fn spec ->
        commands =
          Enum.map(spec, fn
            {:move, n, e, u} -> C.move(n, e, u)
            {:loiter, n, r, turns} -> C.move_and_loiter_turns(n, 0, 0, turns, r)
            {:survey, l, w, s} -> C.survey_area(l, w, s, :south_west)
            {:speed, v, type} -> C.speed(v, type)
            {:delay, s} -> C.delay(s)
            {:photo, 0} -> C.capture_photo()
            {:photo, n} -> C.capture_several_photos(n, 3)
            {:land, yaw, mode} -> C.landing_point(Geo.location(40.5, -7.4, 800), yaw, mode)
            {:servo, ch, pwm} -> C.item(:mav_cmd_do_set_servo, params: [ch, pwm, 0, 0])
          end)

        m = Mission.new("random", [C.home(@home), C.take_off(Geo.location(40.444233, -7.375234, 1200)) | commands])
        back = m |> Mission.to_plan() |> Mission.from_plan!()
        assert Mission.to_items(back) == Mission.to_items(m)
      end),
      numtests: 100
    )
  end

  test "a mission's fence goes out as the plan's geoFence and rallyPoints, in QGroundControl's shapes, and comes back" do
    {:ok, square} = Geo.Shapes.polygon(for {n, e} <- [{-300, -300}, {-300, 300}, {300, 300}, {300, -300}], do: Geo.offset(@home, n, e))
    {:ok, zone} = Geo.Shapes.circle(Geo.offset(@home, 100, 0), 40)
    fence = Dolphin.Fence.new!(include: [square], exclude: [zone], rally: [Geo.offset(@home, 0, 50, 30)])
    m = %{Mission.new("Fenced", [C.home(@home), C.take_off(Geo.offset(@home, 0, 0, 20)), C.return_home_and_land()]) | fence: fence}

    plan = Mission.to_plan(m) |> :jiffy.decode([:return_maps])

    assert %{"geoFence" => %{"polygons" => [%{"inclusion" => true, "polygon" => corners, "version" => 1}], "circles" => [%{"inclusion" => false, "circle" => %{"radius" => 40.0}}], "version" => 2}} =
             plan

    assert length(corners) == 4
    assert %{"rallyPoints" => %{"points" => [[_, _, height]], "version" => 2}} = plan
    assert_in_delta height, 30, 1.0e-9

    assert {:ok, back} = Mission.from_plan(Mission.to_plan(m))
    assert [%Geo.Polygon{points: points}] = back.fence.include
    assert Enum.map(points, &{&1.lat, &1.lon}) == Enum.map(square.points, &{&1.lat, &1.lon})
    assert [%Geo.Circle{radius: 40.0}] = back.fence.exclude
    assert [rally] = back.fence.rally
    assert_in_delta rally.h, @home.h + 30, 1.0e-6
    # A plan without a fence gives a mission without one.
    assert {:ok, %{fence: nil}} = Mission.from_plan(Mission.to_plan(%{m | fence: nil}))

    # A zone the vehicle could not keep is an error naming it.
    bad = put_in(plan, ["geoFence", "polygons"], [%{"inclusion" => true, "polygon" => [[40.0, -7.0], [40.001, -7.0]], "version" => 1}])
    assert {:error, %PlanError{reason: :invalid_fence} = e} = Mission.from_plan(bad)
    assert Exception.message(e) == "invalid geofence or rally points: geoFence polygon 1: a polygon needs at least 3 corners, got 2"
  end

  test "plans that cannot be read are errors naming what is wrong" do
    plan = json(File.read!(@fixture))

    assert {:error, %PlanError{reason: :invalid_json}} = Mission.from_plan("{not json")
    assert {:error, %PlanError{reason: :not_a_plan, detail: ~s("fileType" is "Mission", not "Plan")}} = Mission.from_plan(%{plan | "fileType" => "Mission"})
    assert {:error, %PlanError{reason: :unsupported_version}} = Mission.from_plan(%{plan | "version" => 2})
    assert {:error, %PlanError{reason: :unsupported_version}} = Mission.from_plan(put_in(plan, ["mission", "version"], 1))
    assert {:error, %PlanError{reason: :invalid_home}} = Mission.from_plan(put_in(plan, ["mission", "plannedHomePosition"], [91, 0, 0]))

    survey = %{"type" => "ComplexItem", "complexItemType" => "survey"}
    assert {:error, %PlanError{reason: :unsupported_item, detail: detail}} = Mission.from_plan(put_in(plan, ["mission", "items"], [survey]))
    assert detail =~ "item 1 is a \"ComplexItem\""

    bad_params = put_in(plan, ["mission", "items"], [%{"type" => "SimpleItem", "command" => 16, "frame" => 0, "params" => [1, 2]}])
    assert {:error, %PlanError{reason: :invalid_item}} = Mission.from_plan(bad_params)

    bad_lat = put_in(plan, ["mission", "items"], [%{"type" => "SimpleItem", "command" => 16, "frame" => 0, "params" => [0, 0, 0, 0, 95, 0, 10]}])
    assert {:error, %PlanError{reason: :invalid_item}} = Mission.from_plan(bad_lat)

    assert_raise PlanError, ~r/^not a QGroundControl plan/, fn -> Mission.from_plan!(%{"fileType" => "KML"}) end
    assert {:error, %PlanError{reason: :not_a_plan}} = Mission.from_plan(42)
  end

  test "what is wrong is said in the file's terms: line and column, the field and what it holds, JSON" do
    text = File.read!(@fixture)
    cut = binary_part(text, 0, 41)
    line = length(String.split(cut, "\n"))
    assert message(cut) =~ ~r/^the plan is not valid JSON: line #{line}, column \d+ \(byte 42\): the text ends before the JSON value does$/
    assert message(~s|{"fileType": "Plan",\n "version": tru}|) == ~s|the plan is not valid JSON: line 2, column 13 (byte 34): not true, false or null: "tru}"|
    assert message("") == "the plan is not valid JSON: the file is empty: no JSON value in it"
    assert message("[]") == ~s|not a QGroundControl plan: the file holds an array ([]), not an object with "fileType": "Plan"|
    assert message(~s|{"fileType": "Plan"}|) == ~s|unsupported plan version: no "version" (1 expected)|
    assert message(~s|{"fileType": "Plan", "version": 1}|) == ~s|not a QGroundControl plan: no "mission"|
    assert message(~s|{"fileType": "Plan", "version": 1, "mission": []}|) == ~s|not a QGroundControl plan: "mission" is an array ([]), not an object|

    plan = json(text)
    item = %{"type" => "SimpleItem", "command" => 16, "frame" => 3, "params" => [0, 0, 0, :null, 40.1, -7.2, 30], "autoContinue" => true}
    with_item = fn changes -> put_in(plan, ["mission", "items"], [Map.merge(item, changes)]) end

    assert message(with_item.(%{"command" => "abc"})) == ~s|invalid plan item: item 1: "command" is "abc", not a MAVLink command number (0..65535)|
    assert message(with_item.(%{"command" => :null})) == ~s|invalid plan item: item 1: "command" is null, not a MAVLink command number (0..65535)|
    assert message(Map.delete(item, "frame") |> then(&put_in(plan, ["mission", "items"], [&1]))) == ~s|invalid plan item: item 1: no "frame" (a MAV_FRAME number (0..255) expected)|
    assert message(with_item.(%{"params" => [1, 2]})) == ~s|invalid plan item: item 1: "params" is [1,2], not 7 numbers or nulls|
    assert message(with_item.(%{"params" => [0, 0, "x", 0, 40.1, -7.2, 30]})) == ~s|invalid plan item: item 1: "params" 3 is "x", not a number or null|
    assert message(with_item.(%{"params" => [0, 0, 0, 0, 95, -7.2, 30]})) == ~s|invalid plan item: item 1: "params" 5, the latitude, is 95.0, not within -90..90|
    assert message(with_item.(%{"autoContinue" => "yes"})) == ~s|invalid plan item: item 1: "autoContinue" is "yes", not true or false|
    assert message(put_in(plan, ["mission", "items"], [5])) == ~s|invalid plan item: item 1: it is a number (5), not an object|
    assert message(put_in(plan, ["mission", "items"], %{})) == ~s|not a QGroundControl plan: "mission.items" is {}, not an array of items|

    assert message(put_in(plan, ["mission", "plannedHomePosition"], [91, 0, 0])) ==
             ~s|invalid planned home position: "plannedHomePosition" is [91,0,0], not [latitude, longitude, altitude] with latitude -90..90 and longitude -180..180|

    # No Elixir in any of them.
    for plan <- [with_item.(%{"command" => "abc", "frame" => :null}), "[]", ~s|{"a": }|] do
      refute message(plan) =~ ~r/:null|%\{|=>|\{\d+, :/
    end
  end

  defp message(plan) do
    assert {:error, %PlanError{} = e} = Mission.from_plan(plan)
    Exception.message(e)
  end
end
