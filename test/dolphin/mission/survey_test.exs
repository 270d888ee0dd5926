defmodule Dolphin.Mission.SurveyTest do
  use ExUnit.Case, async: true

  import Dolphin.Property

  alias Dolphin.Geo
  alias Dolphin.Mission
  alias Dolphin.Mission.Command, as: C
  alias Dolphin.Mission.Survey

  doctest Dolphin.Mission.Survey

  @base Geo.location(40.444233, -7.375234, 1200)
  @signs %{north_east: {1, 1}, north_west: {1, -1}, south_east: {-1, 1}, south_west: {-1, -1}}

  # The passes of a survey, measured back from its waypoints: {east, north_from, north_to}.
  defp measured_passes(length, width, spacing, direction) do
    Survey.waypoints(@base, length, width, spacing, direction)
    |> Enum.map(&Geo.ne_offset(@base, &1))
    |> Enum.chunk_every(2)
    |> Enum.map(fn [{n1, e1}, {n2, e2}] ->
      assert_in_delta e1, e2, 1.0e-6, "a pass runs north-south"
      {e1, n1, n2}
    end)
  end

  # The true (geodesic) distance from a point of the rectangle to the nearest
  # pass, each pass spanning the whole length.
  defp distance_to_passes(passes, north, east) do
    p = Geo.offset(@base, north, east)
    passes |> Enum.map(fn {e, _, _} -> Geo.distance(p, Geo.offset(@base, north, e)) end) |> Enum.min()
  end

  defp check_survey(length, width, spacing, direction, samples) do
    {sn, se} = Map.fetch!(@signs, direction)
    passes = measured_passes(length, width, spacing, direction)

    # as many items as uploaded: two per pass
    assert length(passes) * 2 == Survey.item_count(width, spacing)
    items = Mission.to_items(Mission.new("s", [C.home(@base), C.survey_area(length, width, spacing, direction)]))
    assert length(items) == 1 + Survey.item_count(width, spacing)

    # each pass covers the whole length, alternating, the first from the base's edge
    passes
    |> Enum.with_index()
    |> Enum.each(fn {{e, from, to}, k} ->
      {want_from, want_to} = if rem(k, 2) == 0, do: {0.0, sn * length}, else: {sn * length, 0.0}
      assert_in_delta from, want_from, 1.0e-6
      assert_in_delta to, want_to, 1.0e-6
      assert se * e > 0 and se * e < width
    end)

    # neighbours at most `spacing` apart, the outer passes at most spacing / 2 from the edges
    easts = passes |> Enum.map(fn {e, _, _} -> se * e end)
    assert Enum.min(easts) <= spacing / 2 + 1.0e-6
    assert width - Enum.max(easts) <= spacing / 2 + 1.0e-6
    easts |> Enum.chunk_every(2, 1, :discard) |> Enum.each(fn [a, b] -> assert b - a <= spacing + 1.0e-6 end)

    # every point of the rectangle within spacing / 2 of a pass (1 cm of geodesic slack)
    for {fn_, fe} <- samples do
      d = distance_to_passes(passes, sn * fn_ * length, se * fe * width)
      assert d <= spacing / 2 + 0.01, "point #{inspect({fn_, fe})} is #{d} m from the nearest pass"
    end

    :ok
  end

  defp grid(steps), do: for(i <- 0..steps, j <- 0..steps, do: {i / steps, j / steps})

  test "the report's Listing 3 surveys: 3 km × 10 km, 500 m apart, north-east and south-east" do
    check_survey(3000, 10000, 500, :north_east, grid(20))
    check_survey(3000, 10000, 500, :south_east, grid(20))
    assert Survey.pass_count(10000, 500) == 20
  end

  test "all four directions" do
    for direction <- [:north_west, :north_east, :south_west, :south_east] do
      check_survey(1000, 730, 100, direction, grid(12))
    end
  end

  test "pass counts: a narrow area is one pass down its middle; an exact multiple adds none" do
    assert Survey.pass_count(30, 50) == 1
    assert [{{0.0, _}, {100.0, e}}] = Survey.passes(100, 30, 50, :north_east)
    assert_in_delta e, 15.0, 1.0e-9
    assert Survey.pass_count(0.3, 0.1) == 3
    assert Survey.pass_count(0.7, 0.1) == 7
    assert Survey.pass_count(500, 50) == 10
    assert Survey.pass_count(500.01, 50) == 11
  end

  test "passes are parallel geodesics: their lengths and spacing hold on the ellipsoid to a centimetre" do
    points = Survey.waypoints(@base, 3000, 10000, 500, :north_east)

    for [a, b] <- Enum.chunk_every(points, 2) do
      assert_in_delta Geo.distance(a, b), 3000, 0.01
    end

    # corresponding ends of neighbouring passes: pass k ends where pass k + 1 starts
    for [_, end_k, start_next, _] <- Enum.chunk_every(points, 4, 2, :discard) do
      assert_in_delta Geo.distance(end_k, start_next), 500, 0.01
    end
  end

  test "the survey flies at the base's height" do
    assert Enum.all?(Survey.waypoints(@base, 100, 100, 10, :south_west), &(&1.h == 1200.0))
  end

  test "property: every random rectangle is covered within spacing / 2, with 2 · ceil(width / spacing) items" do
    fraction = :proper_types.float(0.0, 1.0)

    case_gen =
      :proper_types.tuple([
        :proper_types.float(10.0, 20_000.0),
        :proper_types.float(10.0, 20_000.0),
        :proper_types.float(0.005, 1.5),
        :proper_types.oneof([:north_west, :north_east, :south_west, :south_east]),
        :proper_types.vector(6, :proper_types.tuple([fraction, fraction]))
      ])

    check(
      forall(case_gen, fn {length, width, spacing_share, direction, samples} ->
        # spacing from width / 200 (200 passes) to 1.5 × width (a single pass)
        spacing = width * spacing_share
        check_survey(length, width, spacing, direction, [{0.0, 0.0}, {1.0, 1.0} | samples])
      end),
      numtests: 60
    )
  end
end
