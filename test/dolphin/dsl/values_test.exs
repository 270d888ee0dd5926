defmodule Dolphin.DSL.ValuesTest do
  use ExUnit.Case, async: true

  import Dolphin.DSL.Values

  doctest Dolphin.DSL.Values

  test "durations are milliseconds, distances metres" do
    assert {days(1), hours(2), minutes(10), seconds(30)} == {86_400_000, 7_200_000, 600_000, 30_000}
    assert minutes(0.5) == 30_000
    assert {km(2.5), meters(7)} == {2500.0, 7}
    assert {percent(90), degrees(15)} == {0.9, 15.0}
  end

  test "locations, areas and distances are Dolphin.Geo's" do
    p = location(40.444233, -7.375234)
    assert p == Dolphin.Geo.location(40.444233, -7.375234, 0)
    assert location(40.444233, -7.375234, 820).h == 820.0
    q = Dolphin.Geo.offset(p, 300, 400)
    assert_in_delta distance(p, q), 500.0, 1.0e-6
    assert near?(p, q, 500.001)
    assert contains?(area(p, km(1)), q)
    refute contains?(area(p, 499), q)
  end

  test "caller mistakes raise ArgumentError" do
    assert_raise ArgumentError, ~r/seconds\/1 takes a number, got: "30"/, fn -> seconds("30") end
    assert_raise ArgumentError, ~r/km\/1 takes a number/, fn -> km(nil) end
    assert_raise ArgumentError, ~r/percent\/1 takes a number/, fn -> percent(:half) end
  end
end
