defmodule Dolphin.Geo.Shapes do
  @moduledoc """
  Plane geometry of fences and zones, pure: whether a point is in a polygon
  or a circle, where a straight leg first enters or leaves one, whether a
  polygon's edges cross, and how close two moving points come. The
  pre-flight check, the simulator's fence and the separation monitor all
  ask these functions.

  Each shape is worked on the plane tangent to the Earth at its first corner
  (or centre): exact to centimetres over the few kilometres of a fence
  (`Dolphin.Geo.tangent_plane/1`). Heights are carried along a leg
  (interpolated), never part of a test.

      iex> alias Dolphin.Geo.Shapes
      iex> home = Dolphin.Geo.location(38.0, -9.0, 0)
      iex> {:ok, zone} = Shapes.polygon(for {n, e} <- [{100, -50}, {100, 50}, {150, 50}, {150, -50}], do: Dolphin.Geo.offset(home, n, e))
      iex> Shapes.contains?(zone, Dolphin.Geo.offset(home, 120, 0))
      true
      iex> {t, at} = Shapes.entry(zone, home, Dolphin.Geo.offset(home, 200, 0, 20))
      iex> {Float.round(t, 3), Float.round(at.h, 1)}
      {0.5, 10.0}
      iex> Shapes.entry(zone, home, Dolphin.Geo.offset(home, 0, 200))
      nil
      iex> Shapes.polygon([home, Dolphin.Geo.offset(home, 10, 0)])
      {:error, "a polygon needs at least 3 corners, got 2"}
  """

  alias Dolphin.Geo
  alias Dolphin.Geo.{Circle, Location, Polygon}

  @type shape :: Polygon.t() | Circle.t()

  @doc """
  A polygon of `points` (locations, in order, not closed: the last joins the
  first), or why it is not one: fewer than three corners, two corners at
  the same place, or two edges that cross (the vehicle could not tell which
  side it is on).
  """
  @spec polygon([Location.t()]) :: {:ok, Polygon.t()} | {:error, String.t()}
  def polygon(points) when is_list(points) do
    cond do
      not Enum.all?(points, &match?(%Location{}, &1)) ->
        {:error, "a polygon's corners are locations, got: #{inspect(Enum.reject(points, &match?(%Location{}, &1)))}"}

      length(points) < 3 ->
        {:error, "a polygon needs at least 3 corners, got #{length(points)}"}

      true ->
        polygon = %Polygon{points: points}

        case crossing(polygon) do
          nil -> {:ok, polygon}
          {:same, i, j} -> {:error, "corners #{i + 1} and #{j + 1} of the polygon are at the same place"}
          {:cross, i, j} -> {:error, "the polygon crosses itself: its edge #{i + 1} (corner #{i + 1} to #{next(i, length(points)) + 1}) crosses its edge #{j + 1}"}
        end
    end
  end

  def polygon(other), do: {:error, "a polygon is a list of locations, got: #{inspect(other)}"}

  @doc "A circle of `radius` metres (more than 0) around `centre`, or why it is not one."
  @spec circle(Location.t(), number()) :: {:ok, Circle.t()} | {:error, String.t()}
  def circle(%Location{} = centre, radius) when is_number(radius) and radius > 0, do: {:ok, %Circle{centre: centre, radius: radius * 1.0}}
  def circle(%Location{}, radius), do: {:error, "a circle's radius is a number of metres, more than 0, got: #{inspect(radius)}"}
  def circle(centre, _radius), do: {:error, "a circle's centre is a location, got: #{inspect(centre)}"}

  @doc "Whether `point` is in `shape` (on its edge counts as in)."
  @spec contains?(shape(), Location.t()) :: boolean()
  def contains?(%Circle{centre: c, radius: r}, %Location{} = point) do
    {n, e} = to_plane(Geo.tangent_plane(c), point)
    n * n + e * e <= r * r
  end

  def contains?(%Polygon{} = polygon, %Location{} = point) do
    {plane, corners} = corners(polygon)
    inside?(corners, to_plane(plane, point))
  end

  @doc """
  Where the straight leg from `a` to `b` first is in `shape`: `{t, point}`
  (`t` from 0 at `a` to 1 at `b`; the point's height interpolated), or nil
  when no point of it is.
  """
  @spec entry(shape(), Location.t(), Location.t()) :: {float(), Location.t()} | nil
  def entry(shape, %Location{} = a, %Location{} = b) do
    cond do
      contains?(shape, a) -> {0.0, a}
      t = List.first(crossings(shape, a, b)) -> {t, along(a, b, t)}
      true -> nil
    end
  end

  @doc "Where the straight leg from `a` to `b` first is out of `shape`: `{t, point}`, or nil when all of it is in."
  @spec exit(shape(), Location.t(), Location.t()) :: {float(), Location.t()} | nil
  def exit(shape, %Location{} = a, %Location{} = b) do
    if contains?(shape, a) do
      # Where it meets the edge and goes out (not where it grazes a corner and stays in).
      case Enum.find(crossings(shape, a, b), &(not contains?(shape, along(a, b, min(&1 + 1.0e-6, 1.0))))) do
        nil -> nil
        t -> {t, along(a, b, t)}
      end
    else
      {0.0, a}
    end
  end

  @doc """
  How close two points moving in a straight line at constant velocity come
  within `horizon` seconds: `{seconds from now, distance}`. Each is
  `{{north, east, up}, {v_north, v_east, v_up}}` in metres and metres per
  second in one frame.

      iex> Dolphin.Geo.Shapes.closest_approach({{0, 0, 0}, {10, 0, 0}}, {{100, 10, 0}, {-10, 0, 0}}, 60)
      {5.0, 10.0}
  """
  @spec closest_approach({tuple(), tuple()}, {tuple(), tuple()}, number()) :: {float(), float()}
  def closest_approach({{pn, pe, pu}, {vn, ve, vu}}, {{qn, qe, qu}, {wn, we, wu}}, horizon) do
    {dn, de, du} = {qn - pn, qe - pe, qu - pu}
    {rn, re, ru} = {wn - vn, we - ve, wu - vu}
    speed2 = rn * rn + re * re + ru * ru
    t = if speed2 == 0, do: 0.0, else: max(0.0, min(horizon * 1.0, -(dn * rn + de * re + du * ru) / speed2))
    {cn, ce, cu} = {dn + rn * t, de + re * t, du + ru * t}
    {t * 1.0, :math.sqrt(cn * cn + ce * ce + cu * cu)}
  end

  # --- on the plane -------------------------------------------------------------

  # The t in [0, 1] at which the leg meets the shape's edge, in order.
  defp crossings(%Circle{centre: c, radius: r}, a, b) do
    plane = Geo.tangent_plane(c)
    {an, ae} = to_plane(plane, a)
    {bn, be} = to_plane(plane, b)
    {dn, de} = {bn - an, be - ae}
    qa = dn * dn + de * de
    qb = 2 * (an * dn + ae * de)
    qc = an * an + ae * ae - r * r
    disc = qb * qb - 4 * qa * qc

    cond do
      qa == 0 or disc < 0 -> []
      true -> Enum.filter([(-qb - :math.sqrt(disc)) / (2 * qa), (-qb + :math.sqrt(disc)) / (2 * qa)], &(&1 >= 0 and &1 <= 1))
    end
  end

  defp crossings(%Polygon{} = polygon, a, b) do
    {plane, corners} = corners(polygon)
    p = to_plane(plane, a)
    q = to_plane(plane, b)

    corners
    |> edges()
    |> Enum.flat_map(fn {c, d} -> List.wrap(intersection(p, q, c, d)) end)
    |> Enum.sort()
  end

  # The t along p→q where it meets the segment c→d, or nil.
  defp intersection({pn, pe}, {qn, qe}, {cn, ce}, {dn, de}) do
    {rn, re} = {qn - pn, qe - pe}
    {sn, se} = {dn - cn, de - ce}
    denom = rn * se - re * sn

    if denom == 0 do
      nil
    else
      t = ((cn - pn) * se - (ce - pe) * sn) / denom
      u = ((cn - pn) * re - (ce - pe) * rn) / denom
      if t >= 0 and t <= 1 and u >= 0 and u <= 1, do: t
    end
  end

  # Even–odd ray casting toward +east.
  defp inside?(corners, {n, e}) do
    corners
    |> edges()
    |> Enum.reduce(false, fn {{an, ae}, {bn, be}}, inside ->
      if an > n != bn > n and e < (be - ae) * (n - an) / (bn - an) + ae, do: not inside, else: inside
    end)
    |> Kernel.or(on_edge?(corners, {n, e}))
  end

  defp on_edge?(corners, {n, e}) do
    Enum.any?(edges(corners), fn {{an, ae}, {bn, be}} ->
      cross = (bn - an) * (e - ae) - (be - ae) * (n - an)
      length = :math.sqrt((bn - an) ** 2 + (be - ae) ** 2)
      abs(cross) <= 1.0e-6 * max(length, 1.0) and n >= min(an, bn) - 1.0e-6 and n <= max(an, bn) + 1.0e-6 and e >= min(ae, be) - 1.0e-6 and e <= max(ae, be) + 1.0e-6
    end)
  end

  # Two corners at one place, or two edges that are not neighbours crossing.
  defp crossing(polygon) do
    {_plane, corners} = corners(polygon)
    indexed = Enum.with_index(corners)
    count = length(corners)

    same = for {p, i} <- indexed, {q, j} <- indexed, i < j, close?(p, q), do: {:same, i, j}

    cross =
      for {{a, b}, i} <- Enum.with_index(edges(corners)),
          {{c, d}, j} <- Enum.with_index(edges(corners)),
          i < j,
          j != next(i, count),
          i != next(j, count),
          intersection(a, b, c, d) != nil,
          do: {:cross, i, j}

    List.first(same ++ cross)
  end

  defp close?({an, ae}, {bn, be}), do: abs(an - bn) < 0.01 and abs(ae - be) < 0.01

  defp next(i, count), do: rem(i + 1, count)

  defp corners(%Polygon{points: [first | _] = points}) do
    plane = Geo.tangent_plane(first)
    {plane, Enum.map(points, &to_plane(plane, &1))}
  end

  defp edges([first | _] = corners), do: Enum.zip(corners, tl(corners) ++ [first])

  defp to_plane(plane, %Location{lat: lat, lon: lon}), do: Geo.to_tangent(plane, lat, lon)

  # The point a fraction t of the way from a to b (on a's tangent plane).
  @doc false
  @spec along(Location.t(), Location.t(), float()) :: Location.t()
  def along(%Location{} = a, %Location{} = b, t) do
    plane = Geo.tangent_plane(a)
    {n, e} = to_plane(plane, b)
    {lat, lon} = Geo.from_tangent(plane, n * t, e * t)
    %Location{lat: lat, lon: lon, h: a.h + (b.h - a.h) * t}
  end
end
