defmodule Dolphin.Geo.ShapesTest do
  # Each function against brute force: points sampled along a leg, judged by
  # an oracle that does not share the function's method.
  use ExUnit.Case, async: true

  import Dolphin.Property

  alias Dolphin.Geo
  alias Dolphin.Geo.Shapes

  doctest Dolphin.Geo.Shapes

  # Hundreds of cases each, thousands of samples: longer than the default on a loaded machine.
  @moduletag timeout: 300_000

  @home Geo.location(38.43462, -8.86118, 0)
  # Points sampled along each leg.
  @samples 1_000

  # A star-shaped polygon round a centre 0–300 m from home: corners at sorted
  # angles, each at its own distance (always simple, never crossing itself).
  defp star do
    corner = :proper_types.tuple([:proper_types.integer(0, 3599), :proper_types.integer(20, 400)])
    :proper_types.tuple([:proper_types.integer(-300, 300), :proper_types.integer(-300, 300), :proper_types.resize(12, :proper_types.non_empty(:proper_types.list(corner)))])
  end

  defp star_polygon({cn, ce, corners}) do
    corners = corners |> Enum.uniq_by(&elem(&1, 0)) |> Enum.sort()
    centre = Geo.offset(@home, cn, ce)
    points = for {tenths, r} <- corners, do: Geo.offset(centre, r * :math.cos(tenths / 1800 * :math.pi()), r * :math.sin(tenths / 1800 * :math.pi()))
    {centre, corners, points}
  end

  # The oracle: in a star polygon, a point is in when it is nearer the centre
  # than the boundary along its own bearing (the ray from the centre meets one edge).
  defp star_inside?({centre, corners, _points}, p) do
    {n, e} = Geo.ne_offset(centre, p)
    d = :math.sqrt(n * n + e * e)
    angle = :math.atan2(e, n)
    vertices = for {tenths, r} <- corners, do: {tenths / 1800 * :math.pi(), r}
    [{a0, _} | _] = vertices

    {{a1, r1}, {a2, r2}} =
      vertices
      |> Enum.zip(tl(vertices) ++ [{a0 + 2 * :math.pi(), elem(hd(vertices), 1)}])
      |> Enum.find(fn {{a1, _}, {a2, _}} -> in_arc?(angle, a1, a2) end)

    # Where the ray at `angle` meets the edge between the two corners (polar line through two points).
    {x1, y1} = {r1 * :math.cos(a1), r1 * :math.sin(a1)}
    {x2, y2} = {r2 * :math.cos(a2), r2 * :math.sin(a2)}
    {dx, dy} = {:math.cos(angle), :math.sin(angle)}
    boundary = (x1 * y2 - y1 * x2) / (dx * (y2 - y1) - dy * (x2 - x1))
    d <= boundary
  end

  defp in_arc?(angle, a1, a2) do
    two_pi = 2 * :math.pi()
    span = a2 - a1
    rel = :math.fmod(:math.fmod(angle - a1, two_pi) + two_pi, two_pi)
    span >= two_pi or rel <= span
  end

  defp leg, do: :proper_types.tuple([:proper_types.integer(-800, 800), :proper_types.integer(-800, 800), :proper_types.integer(-800, 800), :proper_types.integer(-800, 800)])

  defp sample(a, b), do: for(i <- 0..@samples, do: {i / @samples, Shapes.along(a, b, i / @samples)})

  # A star is a polygon round its centre when its corners go all round it:
  # three at least, no gap of half a turn between two (150° at most: a gap
  # near half a turn makes a sliver a few centimetres wide, where the
  # oracle's projection and the plane's differ by more than its width).
  defp polygon_of(star) do
    {_, corners, points} = star
    angles = Enum.map(corners, &elem(&1, 0))
    gaps = Enum.zip(angles, tl(angles) ++ [hd(angles) + 3600]) |> Enum.map(fn {a, b} -> b - a end)
    if length(corners) >= 3 and Enum.max(gaps) <= 1500, do: Shapes.polygon(points), else: :not_round
  end

  test "a point is in a polygon as the oracle says" do
    check(
      forall({star(), :proper_types.list(:proper_types.tuple([:proper_types.integer(-800, 800), :proper_types.integer(-800, 800)]))}, fn {gen, points} ->
        s = star_polygon(gen)

        case polygon_of(s) do
          {:ok, polygon} -> for {n, e} <- points, p = Geo.offset(@home, n, e), do: assert(Shapes.contains?(polygon, p) == star_inside?(s, p), "#{n}, #{e}")
          _ -> :ok
        end

        true
      end),
      numtests: 200
    )
  end

  test "a leg enters a polygon where the first sampled point in it is; leaves it where the first point out is" do
    check(
      forall({star(), leg()}, fn {gen, {an, ae, bn, be}} ->
        s = star_polygon(gen)
        a = Geo.offset(@home, an, ae)
        b = Geo.offset(@home, bn, be, 50)
        step = 1 / @samples

        with {:ok, polygon} <- polygon_of(s) do
          samples = sample(a, b)
          first_in = Enum.find_value(samples, fn {t, p} -> if star_inside?(s, p), do: t end)
          first_out = Enum.find_value(samples, fn {t, p} -> if not star_inside?(s, p), do: t end)

          case Shapes.entry(polygon, a, b) do
            nil ->
              assert first_in == nil

            # A leg that clips a corner for less than a sample step has no sample in: the oracle
            # sees it out again one step on.
            {t, at} when first_in == nil ->
              assert and_height(at, a, b, t) and not star_inside?(s, Shapes.along(a, b, min(t + step, 1.0)))

            {t, at} ->
              assert abs(first_in - t) <= 2 * step and and_height(at, a, b, t)
          end

          case Shapes.exit(polygon, a, b) do
            nil -> assert first_out == nil
            {t, _at} -> assert first_out != nil and abs(first_out - t) <= 2 * step, "exit at #{t}, first sampled out at #{inspect(first_out)}"
          end
        end

        true
      end),
      numtests: 200
    )
  end

  defp and_height(at, a, b, t), do: abs(at.h - (a.h + (b.h - a.h) * t)) < 1.0e-6

  test "a leg enters and leaves a circle where the sampled points, judged by the geodesic distance, say" do
    check(
      forall({:proper_types.integer(-300, 300), :proper_types.integer(-300, 300), :proper_types.integer(5, 500), leg()}, fn {cn, ce, r, {an, ae, bn, be}} ->
        centre = Geo.offset(@home, cn, ce)
        {:ok, circle} = Shapes.circle(centre, r)
        a = Geo.offset(@home, an, ae)
        b = Geo.offset(@home, bn, be)
        samples = sample(a, b)
        # A sample within a centimetre of the edge is either.
        near_edge? = Enum.any?(samples, fn {_, p} -> abs(Geo.distance(centre, p) - r) < 0.01 end)
        first_in = Enum.find_value(samples, fn {t, p} -> if Geo.distance(centre, p) <= r, do: t end)
        first_out = Enum.find_value(samples, fn {t, p} -> if Geo.distance(centre, p) > r, do: t end)
        step = 1 / @samples

        unless near_edge? do
          case Shapes.entry(circle, a, b) do
            nil -> assert first_in == nil
            {t, _} -> assert first_in != nil and abs(first_in - t) <= 2 * step
          end

          case Shapes.exit(circle, a, b) do
            nil -> assert first_out == nil
            {t, _} -> assert first_out != nil and abs(first_out - t) <= 2 * step
          end
        end

        true
      end),
      numtests: 200
    )
  end

  test "two moving points come no closer than the closest approach says, and that close at its time" do
    v = :proper_types.integer(-30, 30)
    p = :proper_types.integer(-500, 500)

    check(
      forall({{p, p, p}, {v, v, v}, {p, p, p}, {v, v, v}, :proper_types.integer(1, 120)}, fn {p0, v0, q0, w0, horizon} ->
        {t, d} = Shapes.closest_approach({p0, v0}, {q0, w0}, horizon)
        at = fn {x, y, z}, {vx, vy, vz}, s -> {x + vx * s, y + vy * s, z + vz * s} end
        dist = fn s -> apart(at.(p0, v0, s), at.(q0, w0, s)) end
        sampled = for i <- 0..2_000, do: dist.(horizon * i / 2_000)
        assert t >= 0 and t <= horizon
        assert_in_delta dist.(t), d, 1.0e-6
        assert d <= Enum.min(sampled) + 1.0e-6
      end),
      numtests: 200
    )
  end

  defp apart({x1, y1, z1}, {x2, y2, z2}), do: :math.sqrt((x1 - x2) ** 2 + (y1 - y2) ** 2 + (z1 - z2) ** 2)

  test "a polygon that crosses itself, or has two corners at one place, or too few, is refused with why" do
    corners = for {n, e} <- [{0, 0}, {100, 100}, {100, 0}, {0, 100}], do: Geo.offset(@home, n, e)
    assert {:error, "the polygon crosses itself: its edge 1 (corner 1 to 2) crosses its edge 3"} = Shapes.polygon(corners)
    assert {:error, "corners 1 and 3 of the polygon are at the same place"} = Shapes.polygon([@home, Geo.offset(@home, 50, 0), @home, Geo.offset(@home, 0, 50)])
    assert {:error, "a polygon's corners are locations" <> _} = Shapes.polygon([@home, {1, 2}, @home])
    assert {:error, "a circle's radius is a number of metres, more than 0, got: -5"} = Shapes.circle(@home, -5)
  end
end
