defmodule Dolphin.FenceTest do
  # A fence put on a vehicle and breached, on the simulator and on
  # ArduCopter SITL alike (docs/ardupilot.md, "Fences"), in a Dolphin.Instance
  # of the test's own (vehicles, fleet, clock): async; `make test` runs its
  # SITL tests alone (--max-cases 1).
  use ExUnit.Case, async: true

  alias Dolphin.{Engine, Fence, Geo, Mission, Vehicles}
  alias Dolphin.Geo.Shapes
  alias Dolphin.Mission.Command, as: C
  alias Dolphin.Test.{Backend, Wait}

  @moduletag timeout: 300_000

  doctest Dolphin.Fence

  setup do
    Dolphin.Test.Instance.start!()
    Dolphin.Fleet.set_source({Dolphin.Fleet.MAVLinkSource, nil})
    :ok
  end

  # A fence round home: a square of 600 m, a no-fly zone 80–120 m north, a 60 m ceiling, rally point 50 m east.
  defp fence(home, on_breach) do
    square = for {n, e} <- [{-300, -300}, {-300, 300}, {300, 300}, {300, -300}], do: Geo.offset(home, n, e)
    zone = for {n, e} <- [{80, -50}, {80, 50}, {120, 50}, {120, -50}], do: Geo.offset(home, n, e)
    {:ok, square} = Shapes.polygon(square)
    {:ok, zone} = Shapes.polygon(zone)
    Fence.new!(include: [square], exclude: [zone], max_altitude: 60, on_breach: on_breach, rally: [Geo.offset(home, 0, 50, 30)])
  end

  # Take off to 20 m, fly 200 m north through the zone, come home and land.
  defp through(home, fence) do
    Mission.new("Through", [C.home(home), C.take_off(Geo.offset(home, 0, 0, 20)), C.move(200, 0, 0), C.return_home_and_land()]) |> Map.put(:fence, fence)
  end

  defp flies_into_the_zone(backend) do
    [id] = Backend.start(backend, 1)
    home = Backend.home(id)
    {:ok, _} = Dolphin.Fleet.pick(Dolphin.Instance.names().fleet, self(), id: id)
    fence = fence(home, :rtl)

    # Put on, read back as it was sent, enabled with its action and ceiling.
    assert :ok = Vehicles.Fences.apply(id, fence, home, :copter)
    items = Fence.to_items(fence, home)
    assert {:ok, back} = Vehicles.download_mission(id, mission_type: :fence)
    assert :ok = Vehicles.Fences.compare(:fence, items.fence, back)
    assert {:ok, rally} = Vehicles.download_mission(id, mission_type: :rally)
    assert :ok = Vehicles.Fences.compare(:rally, items.rally, rally)
    assert {:ok, 1.0} = Vehicles.read_param(id, "FENCE_ENABLE")
    assert {:ok, 1.0} = Vehicles.read_param(id, "FENCE_ACTION")
    assert {:ok, 60.0} = Vehicles.read_param(id, "FENCE_ALT_MAX")
    assert {:ok, 5.0} = Vehicles.read_param(id, "FENCE_TYPE")

    # Flown through the zone: breached, RTL, and the script is told why.
    assert {:error, %Engine.Failure{reason: %Mission.Failure{cause: {:left_auto, "RTL"}, status_texts: texts}}} = Engine.run(Engine.on(through(home, fence), [id]))
    said = for {_, text} <- texts, do: text
    assert "Polygon fence breached" in said, inspect(said)
    assert "Manual recovery started" in said
    # Its RTL brings it back out of the zone, down and disarmed.
    Wait.until(fn -> match?({:ok, %{armed?: false}}, Vehicles.view(id)) end, 6_000, fn -> inspect(Vehicles.view(id)) end)
    assert Enum.any?(Vehicles.status_texts(id), fn {_, text} -> text == "Fence breach cleared" end)
    {:ok, view} = Vehicles.view(id)
    {:ok, zone} = Shapes.polygon(for {n, e} <- [{80, -50}, {80, 50}, {120, 50}, {120, -50}], do: Geo.offset(home, n, e))
    refute Shapes.contains?(zone, view.position)

    # Released, it is given back as it was found: no fence, no rally point, its parameters as they were.
    :ok = Dolphin.Fleet.release(Dolphin.Instance.names().fleet, self(), [id])

    Wait.until(
      fn ->
        match?({:ok, 7.0}, Vehicles.read_param(id, "FENCE_TYPE")) and match?({:ok, 100.0}, Vehicles.read_param(id, "FENCE_ALT_MAX")) and
          match?({:ok, []}, Vehicles.download_mission(id, mission_type: :rally))
      end,
      3_000
    )

    assert {:ok, []} = Vehicles.download_mission(id, mission_type: :fence)
    assert {:ok, 0.0} = Vehicles.read_param(id, "FENCE_ENABLE")
    assert {:ok, 1.0} = Vehicles.read_param(id, "FENCE_ACTION")
    for text <- said, text =~ ~r/fence|recovery/i, into: MapSet.new(), do: text
  end

  # A rover driven at a no-fly zone: ArduRover stops short of it (FENCE_MARGIN,
  # 2 m) and stands there in AUTO without a word; the task fails once it has
  # stood still for a minute, saying where. Returns how far it got.
  defp drives_at_the_zone(backend) do
    [id] = Backend.start(backend, [rover: 1], speedup: if(backend == :sim, do: 20, else: 10))
    home = Backend.home(id)
    {:ok, _} = Dolphin.Fleet.pick(Dolphin.Instance.names().fleet, self(), id: id)
    {:ok, zone} = Shapes.polygon(for {n, e} <- [{80, -50}, {80, 50}, {120, 50}, {120, -50}], do: Geo.offset(home, n, e))
    fence = Fence.new!(exclude: [zone], on_breach: :hold)
    drive = Mission.new("Drive", [C.home(home), C.move(200, 0, 0)]) |> Map.put(:fence, fence)

    assert {:error, %Engine.Failure{reason: %Mission.Failure{cause: {:stuck, 60, {1, 1, "NAV_WAYPOINT", short}}} = failure}} = Engine.run(Engine.on(drive, [id]))
    assert Exception.message(failure) =~ ~r/has stood still for 60 s of the mission, \d+ m short of item 1 of 1 \(NAV_WAYPOINT\), in AUTO/
    # ArduRover's fence action for :hold is HOLD (FENCE_ACTION 2), and it never breached.
    assert {:ok, 2.0} = Vehicles.read_param(id, "FENCE_ACTION")
    {:ok, view} = Vehicles.view(id)
    refute Shapes.contains?(zone, view.position)
    {north, _} = Geo.ne_offset(home, view.position)
    # Released, given back as it was found (before the vehicle is stopped).
    :ok = Dolphin.Fleet.release(Dolphin.Instance.names().fleet, self(), [id])
    assert :ok = Vehicles.Fences.await_returns(30_000)
    assert {:ok, 1.0} = Vehicles.read_param(id, "FENCE_ACTION")
    {round(north), short}
  end

  test "the simulator: a rover driven at a no-fly zone stops short of it as ArduRover does, and the task fails saying where it stands" do
    assert {78, 122} = drives_at_the_zone(:sim)
  end

  if Dolphin.SITL.available?(:rover) do
    @tag :sitl
    test "ArduRover SITL: stops short of the no-fly zone, and the task fails as on the simulator" do
      assert {78, 122} = drives_at_the_zone(:sitl)
    end
  end

  # What ArduCopter SITL said at the breach (docs/ardupilot.md), which the simulator must say too.
  @breach_texts MapSet.new(["Polygon fence breached", "Manual recovery started"])

  test "the simulator: a fence put on a copter is read back as sent; flown into its no-fly zone, it breaches it and returns, the mission fails saying so; released, the copter is given back as it was found" do
    assert flies_into_the_zone(:sim) == @breach_texts
  end

  if Dolphin.SITL.available?(:copter) do
    @tag :sitl
    test "ArduCopter SITL: the same fence, read back as sent; the same breach, texts, RTL and failure as the simulator's" do
      assert flies_into_the_zone(:sitl) == @breach_texts
    end
  end
end
