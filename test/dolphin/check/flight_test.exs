defmodule Dolphin.Check.FlightTest do
  # Where a dry run's stand-in flight leaves its vehicle when it is stopped:
  # part way along its estimate's way, as it would fly it.
  use ExUnit.Case, async: true

  alias Dolphin.Check.Flight
  alias Dolphin.Geo

  @ground Geo.location(40.444233, -7.375234, 820)

  # On the ground at home, 20 s to a point 200 m east and 30 m up, 10 s to
  # one 100 m north of that.
  defp estimate do
    up_east = Geo.offset(@ground, 0, 200, 30)
    north = Geo.offset(up_east, 100, 0, 0)
    %{start_at: @ground, path: [{20.0, up_east, true, 1}, {30.0, north, true, 2}]}
  end

  defp north_east_of_ground(at) do
    {n, e} = Geo.to_tangent(Geo.tangent_plane(@ground), at.lat, at.lon)
    {Float.round(n, 1), Float.round(e, 1), Float.round(at.h - @ground.h, 1)}
  end

  test "stopped between two points of its way, it is that far along from the one reached to the next, and in the air" do
    assert {at, true} = Flight.position_at(estimate(), false, 5.0)
    assert north_east_of_ground(at) == {0.0, 50.0, 7.5}

    assert {at, true} = Flight.position_at(estimate(), false, 25.0)
    assert north_east_of_ground(at) == {50.0, 200.0, 30.0}
  end

  test "at a point of its way it is there; past its last, at its last; before it flies, where it stands" do
    assert {at, true} = Flight.position_at(estimate(), false, 20.0)
    assert north_east_of_ground(at) == {0.0, 200.0, 30.0}
    assert {at, true} = Flight.position_at(estimate(), false, 90.0)
    assert north_east_of_ground(at) == {100.0, 200.0, 30.0}
    assert {@ground, false} = Flight.position_at(%{estimate() | path: []}, false, 5.0)
    assert {nil, false} = Flight.position_at(%{start_at: nil, path: []}, false, 5.0)
  end
end
