defmodule Dolphin.Report.Simplify do
  @moduledoc """
  Fewer points, the same picture: what keeps a flight report of a long run
  small and quick to draw.

  `track/2` is Douglas–Peucker: the points it keeps are such that no point
  dropped lies further than `tolerance` from the polyline kept.

      iex> Dolphin.Report.Simplify.track([{0.0, 0.0}, {1.0, 0.2}, {2.0, 0.0}, {3.0, 5.0}], 0.5)
      [{0.0, 0.0}, {2.0, 0.0}, {3.0, 5.0}]

  `series/2` thins a time series to at most about `2 * buckets` points and
  keeps each bucket's lowest and highest value, so a dip in the battery or a
  spike of speed still shows.

      iex> Dolphin.Report.Simplify.series([{0, 5}, {1, 1}, {2, 9}, {3, 4}], 1)
      [{1, 1}, {2, 9}]
  """

  @type point :: {number(), number()}

  # Points of a window of a long track simplified on its own (see track/2).
  @window 1_000

  @doc """
  Douglas–Peucker with `tolerance` in the points' unit; the first and last
  points always stay.

  A long track is cut in windows of #{@window} points, simplified one by
  one (their ends stay: a point more per window): Douglas–Peucker costs its
  points times the corners it finds, and an hour of a survey has hundreds of
  corners.
  """
  @spec track([point()], number()) :: [point()]
  def track(points, tolerance) when tolerance <= 0, do: points

  def track(points, tolerance) do
    case length(points) do
      n when n < 3 -> points
      n when n <= 2 * @window -> douglas_peucker(points, tolerance)
      _ ->
        [first | rest] = points |> windows([]) |> Enum.map(&douglas_peucker(&1, tolerance))
        first ++ Enum.flat_map(rest, &tl/1)
    end
  end

  # Windows that share their end points.
  defp windows(points, acc) do
    case Enum.split(points, @window) do
      {window, []} -> Enum.reverse([window | acc])
      {window, rest} -> windows([List.last(window) | rest], [window | acc])
    end
  end

  defp douglas_peucker(points, _tolerance) when length(points) < 3, do: points

  defp douglas_peucker(points, tolerance) do
    t = List.to_tuple(points)
    n = tuple_size(t)
    keep = split([{0, n - 1}], t, tolerance * tolerance, [0, n - 1])
    keep |> Enum.sort() |> Enum.dedup() |> Enum.map(&elem(t, &1))
  end

  # An explicit stack of spans: no recursion depth to fear on a long straight
  # flight cut into a few thousand pieces.
  defp split([], _t, _tol2, keep), do: keep
  defp split([{a, b} | rest], t, tol2, keep) when b - a < 2, do: split(rest, t, tol2, keep)

  defp split([{a, b} | rest], t, tol2, keep) do
    {i, d2} = farthest(elem(t, a), elem(t, b), t, a + 1, b, a, -1.0)

    if d2 > tol2,
      do: split([{a, i}, {i, b} | rest], t, tol2, [i | keep]),
      else: split(rest, t, tol2, keep)
  end

  defp farthest({px, py} = p, {qx, qy}, t, i, b, best, best_d2) do
    dx = qx - px
    dy = qy - py
    farthest(p, dx, dy, dx * dx + dy * dy, t, i, b, best, best_d2)
  end

  defp farthest(_p, _dx, _dy, _len2, _t, i, b, best, best_d2) when i >= b, do: {best, best_d2}

  defp farthest(p, dx, dy, len2, t, i, b, best, best_d2) do
    d2 = distance2(elem(t, i), p, dx, dy, len2)

    if d2 > best_d2,
      do: farthest(p, dx, dy, len2, t, i + 1, b, i, d2),
      else: farthest(p, dx, dy, len2, t, i + 1, b, best, best_d2)
  end

  # Squared distance from point m to the segment from p along (dx, dy); the
  # hot loop of a report, so no closure and no min/max calls.
  defp distance2({mx, my}, {px, py}, _dx, _dy, len2) when len2 == 0, do: (mx - px) * (mx - px) + (my - py) * (my - py)

  defp distance2({mx, my}, {px, py}, dx, dy, len2) do
    ax = mx - px
    ay = my - py
    dot = ax * dx + ay * dy

    cond do
      dot <= 0 ->
        ax * ax + ay * ay

      dot >= len2 ->
        bx = ax - dx
        by = ay - dy
        bx * bx + by * by

      true ->
        cross = ax * dy - ay * dx
        cross * cross / len2
    end
  end

  @doc "At most about `2 * buckets` points of a series sorted by time: each bucket's minimum and maximum, in time order."
  @spec series([point()], pos_integer()) :: [point()]
  def series([], _buckets), do: []

  def series(points, buckets) when is_integer(buckets) and buckets > 0 do
    if length(points) <= 2 * buckets do
      points
    else
      [{t0, _} = first | rest] = points
      {t1, _} = List.last(points)
      width = max((t1 - t0) / buckets, 1.0e-9)
      bucket = fn {t, _} -> min(trunc((t - t0) / width), buckets - 1) end
      buckets(rest, bucket, bucket.(first), first, first, [])
    end
  end

  # One pass: the lowest and highest point of the current bucket.
  defp buckets([], _bucket, _b, low, high, acc), do: Enum.reverse(extremes(low, high, acc))

  defp buckets([p | rest], bucket, b, low, high, acc) do
    case bucket.(p) do
      ^b -> buckets(rest, bucket, b, lower(p, low), higher(p, high), acc)
      next -> buckets(rest, bucket, next, p, p, extremes(low, high, acc))
    end
  end

  defp lower({_, y} = p, {_, ly}) when y < ly, do: p
  defp lower(_p, low), do: low
  defp higher({_, y} = p, {_, hy}) when y > hy, do: p
  defp higher(_p, high), do: high

  defp extremes(same, same, acc), do: [same | acc]
  defp extremes({tl, _} = low, {th, _} = high, acc) when tl <= th, do: [high, low | acc]
  defp extremes(low, high, acc), do: [low, high | acc]
end
