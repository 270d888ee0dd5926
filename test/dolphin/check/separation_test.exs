defmodule Dolphin.Check.SeparationTest do
  use ExUnit.Case, async: true

  import Dolphin.Property

  alias Dolphin.Check.Separation
  alias Dolphin.Geo

  @base Geo.location(40.444233, -7.375234, 820)
  @limits %{horizontal: 20.0, vertical: 10.0}

  defp timeline(id, points), do: %{vehicle: id, points: points, missions: [{0, "M#{id}", 10 + id}]}

  test "two vehicles that pass within the limits once: one conflict, at its closest moment, where and how close" do
    # A flies east along the base's parallel, B north along its meridian: both at the base at 30 s.
    a = timeline(1, [{0, Geo.offset(@base, 0, -300, 30), true}, {60_000, Geo.offset(@base, 0, 300, 30), true}])
    b = timeline(2, [{0, Geo.offset(@base, -300, 0, 30), true}, {60_000, Geo.offset(@base, 300, 0, 30), true}])
    assert [%{vehicles: {1, 2}, at_ms: at, horizontal: h, vertical: v}] = Separation.conflicts([a, b], @limits)
    # Within 20 m from 28.6 s to 31.4 s, closest at 30 s.
    assert at == 30_000 and h < 0.01 and v < 0.01
  end

  test "apart in height, or both standing on the ground, is no conflict; an episode is one finding however long" do
    over = timeline(2, [{0, Geo.offset(@base, -300, 0, 45), true}, {60_000, Geo.offset(@base, 300, 0, 45), true}])
    a = timeline(1, [{0, Geo.offset(@base, 0, -300, 30), true}, {60_000, Geo.offset(@base, 0, 300, 30), true}])
    assert Separation.conflicts([a, over], @limits) == []

    parked = [timeline(1, [{0, @base, false}, {60_000, @base, false}]), timeline(2, [{0, Geo.offset(@base, 5, 0), false}])]
    assert Separation.conflicts(parked, @limits) == []

    # One hovers where the other stands for a minute: one finding.
    hover = [timeline(1, [{0, Geo.offset(@base, 0, 0, 5), true}, {60_000, Geo.offset(@base, 0, 0, 5), true}]), timeline(2, [{0, @base, false}])]
    assert [%{at_ms: 0}] = Separation.conflicts(hover, @limits)
  end

  test "a submarine is kept apart from submarines, not from what flies or floats above it" do
    plane = Map.put(timeline(1, [{0, @base, true}, {10_000, @base, true}]), :airframe, :plane)
    sub = Map.put(timeline(2, [{0, @base, true}, {10_000, @base, true}]), :airframe, :sub)
    other_sub = Map.put(timeline(3, [{0, @base, true}, {10_000, @base, true}]), :airframe, :sub)
    assert [%{vehicles: {2, 3}}] = Separation.conflicts([plane, sub, other_sub], @limits)
  end

  test "only pairs whose reach meets are tried: the same conflicts as trying every pair, for fleets anywhere on the map" do
    check(
      forall({:proper_types.integer(-8_995, 8_995), :proper_types.integer(-17_999, 17_999), :proper_types.list(track())}, fn {lat, lon, tracks} ->
        base = Geo.location(lat / 100, lon / 100, 100)

        timelines =
          for {{{n0, e0}, steps, up}, id} <- Enum.with_index(tracks, 1) do
            points = for {{n, e}, k} <- Enum.with_index(steps), do: {k * 10_000, Geo.offset(base, (n0 + n) * 1.0, (e0 + e) * 1.0, up * 1.0), true}
            timeline(id, points)
          end

        assert Separation.conflicts(timelines, @limits) == Separation.conflicts(timelines, @limits, all_pairs: true)
        true
      end),
      numtests: 150,
      max_size: 12
    )
  end

  # A vehicle's one to three points, 10 s apart, a few metres about its own
  # place within 40 m of the base, at one of a few heights: pairs near and far from the
  # limits' edge, boxes that meet and boxes that do not.
  defp track do
    place = {:proper_types.integer(-40, 40), :proper_types.integer(-40, 40)}
    step = {:proper_types.integer(-3, 3), :proper_types.integer(-3, 3)}
    {place, :proper_types.oneof([[step], [step, step], [step, step, step]]), :proper_types.oneof([20, 25, 40])}
  end

  test "the finding names both missions and is at the line of the later one" do
    a = %{timeline(1, [{0, @base, true}, {10_000, @base, true}]) | missions: [{0, "Early", 12}]}
    b = %{timeline(2, [{5_000, Geo.offset(@base, 5, 0), true}, {10_000, Geo.offset(@base, 5, 0), true}]) | missions: [{5_000, "Late", 14}]}
    [conflict] = Separation.conflicts([a, b], @limits)
    finding = Separation.finding(conflict, "x.exs", @limits, :error)
    assert finding.line == 14
    assert finding.message =~ ~s|(mission "Early" on vehicle 1 and mission "Late" on vehicle 2)|
  end
end
