defmodule Dolphin.Report.SimplifyTest do
  use ExUnit.Case, async: true

  import Dolphin.Property

  alias Dolphin.Report.Simplify

  doctest Simplify

  # Distance from m to the segment p-q.
  defp distance({mx, my}, {px, py}, {qx, qy}) do
    {dx, dy} = {qx - px, qy - py}
    len2 = dx * dx + dy * dy
    u = if len2 == 0, do: 0.0, else: min(1.0, max(0.0, ((mx - px) * dx + (my - py) * dy) / len2))
    :math.sqrt(:math.pow(mx - (px + u * dx), 2) + :math.pow(my - (py + u * dy), 2))
  end

  # Every point dropped lies within `tol` of the kept polyline between the
  # kept points around it.
  defp within?(points, kept, tol) do
    indexed = Enum.with_index(points)
    kept_idx = Enum.map(kept, fn k -> Enum.find_index(points, &(&1 == k)) end)

    kept_idx
    |> Enum.chunk_every(2, 1, :discard)
    |> Enum.all?(fn [a, b] ->
      p = Enum.at(points, a)
      q = Enum.at(points, b)
      Enum.all?(for {m, i} <- indexed, i > a and i < b, do: distance(m, p, q) <= tol + 1.0e-9)
    end)
  end

  defp walk(steps) do
    Enum.scan(steps, {0.0, 0.0}, fn {dx, dy}, {x, y} -> {x + dx / 10, y + dy / 10} end)
  end

  test "a dropped point is never further than the tolerance from the track kept; the ends stay" do
    step = :proper_types.tuple([:proper_types.integer(-30, 30), :proper_types.integer(-30, 30)])

    check(
      forall(:proper_types.list(step), fn steps ->
        points = Enum.uniq(walk(steps))
        kept = Simplify.track(points, 1.0)
        assert kept == [] or (hd(kept) == hd(points) and List.last(kept) == List.last(points))
        assert within?(points, kept, 1.0)
      end),
      numtests: 200
    )
  end

  test "a long track is simplified in windows and still within the tolerance" do
    :rand.seed(:exsss, {7, 8, 9})
    # A lawnmower of 5,000 points with noise of ±0.3 m: a few corners are left.
    points =
      for i <- 0..4_999 do
        leg = div(i, 500)
        along = rem(i, 500) * 1.0
        y = if rem(leg, 2) == 0, do: along, else: 499 - along
        {leg * 40.0 + (:rand.uniform() - 0.5) * 0.6, y + (:rand.uniform() - 0.5) * 0.6}
      end

    kept = Simplify.track(points, 1.0)
    assert length(kept) < 60
    assert hd(kept) == hd(points) and List.last(kept) == List.last(points)
    assert within?(points, kept, 1.0)
  end

  test "a series keeps each bucket's extremes, in time order" do
    series = for t <- 0..9_999, do: {t * 1.0, if(t == 5_000, do: -50.0, else: :math.sin(t / 100))}
    thin = Simplify.series(series, 100)
    assert length(thin) <= 200
    assert {5_000.0, -50.0} in thin
    assert thin == Enum.sort_by(thin, &elem(&1, 0))
    assert Simplify.series(Enum.take(series, 10), 100) == Enum.take(series, 10)
  end
end
