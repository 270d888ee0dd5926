defmodule Dolphin.Check.Separation do
  @moduledoc false
  # Separation between our own vehicles in a dry run: where each vehicle is
  # at every moment of the check's clock (its timeline: the points its
  # missions' estimates reach, at the times they reach them; straight and
  # steady between them, as the estimates fly; still between missions), and
  # every pair that comes closer than the minimum — horizontally and
  # vertically at once — while at least one of them flies. One finding per
  # pair of missions, at its closest moment: when, where, how close, and the
  # missions (the later one's line: the task that brought the conflict).
  # A submarine shares its water with submarines only: it is kept apart
  # from them, not from what flies or floats above it.

  alias Dolphin.Geo

  @type point :: {integer(), Geo.Location.t(), boolean()}
  @type timeline :: %{required(:vehicle) => term(), required(:points) => [point()], required(:missions) => [{integer(), String.t(), pos_integer() | nil}], optional(:airframe) => atom() | nil}
  @type conflict :: %{
          vehicles: {term(), term()},
          at_ms: integer(),
          where: Geo.Location.t(),
          horizontal: float(),
          vertical: float(),
          missions: {{integer(), String.t(), pos_integer() | nil} | nil, {integer(), String.t(), pos_integer() | nil} | nil}
        }

  # Sampling step (clock ms) within each stretch where both move steadily.
  @step_ms 250

  @doc false
  # The finding of a conflict: at the line of the mission that started
  # later (the task that brought the two together).
  @spec finding(conflict(), String.t(), map(), atom()) :: Dolphin.Check.Finding.t()
  def finding(c, file, limits, severity) do
    {va, vb} = c.vehicles
    {ma, mb} = c.missions
    later = [ma, mb] |> Enum.reject(&is_nil/1) |> Enum.max_by(&elem(&1, 0), fn -> nil end)
    line = if later, do: elem(later, 2)
    flying = Enum.map_join(Enum.zip([va, vb], [ma, mb]), " and ", fn {v, m} -> if m, do: ~s(mission "#{elem(m, 1)}" on vehicle #{v}), else: "vehicle #{v}" end)

    message =
      "vehicles #{va} and #{vb} come within #{round(c.horizontal)} m of each other across and #{round(c.vertical)} m in height " <>
        "#{seconds(c.at_ms)} into the run, at #{Float.round(c.where.lat, 6)}, #{Float.round(c.where.lon, 6)} (#{flying}#{times(Map.get(c, :times, 1))}); " <>
        "the least separation is #{round(limits.horizontal)} m across or #{round(limits.vertical)} m in height"

    %Dolphin.Check.Finding{severity: severity, kind: :separation, file: file, line: line, message: message}
  end

  defp times(1), do: ""
  defp times(n), do: "; #{n} times too close in these missions, this the closest"

  defp seconds(ms) when ms < 120_000, do: "#{round(ms / 1000)} s"
  defp seconds(ms), do: "#{Float.round(ms / 60_000, 1)} min"

  @doc false
  # `all_pairs: true` tries every pair, as a test's reference for the sweep.
  @spec conflicts([timeline()], %{horizontal: number(), vertical: number()}, keyword()) :: [conflict()]
  def conflicts(timelines, limits, opts \\ []) do
    timelines = Enum.reject(timelines, &(&1.points == []))
    pairs = if opts[:all_pairs], do: for({a, i} <- Enum.with_index(timelines), {b, j} <- Enum.with_index(timelines), i < j, do: {a, b}), else: near_pairs(timelines, limits)

    for {a, b} <- pairs, same_space?(a, b), conflict <- pair(a, b, limits) do
      conflict
    end
    # Per pair of missions, their closest episode, and how many there were
    # (two surveys side by side meet at every turn).
    |> Enum.group_by(&{&1.vehicles, &1.missions})
    |> Enum.map(fn {_, episodes} -> Map.put(Enum.min_by(episodes, &apart/1), :times, length(episodes)) end)
    |> Enum.sort_by(& &1.at_ms)
  end

  # The pairs (in the timelines' order) whose boxes — the least and most
  # latitude, longitude and height each reaches, widened by the limits —
  # meet: no other pair can come within them. A sweep along the latitude
  # finds them without trying every pair (a thousand vehicles that each
  # stay over their own spot are a thousand boxes that meet none).
  defp near_pairs(timelines, limits) do
    boxes = timelines |> Enum.with_index() |> Enum.map(fn {t, i} -> box(t, i, limits) end) |> Enum.sort_by(& &1.lat_min)
    sweep(boxes, []) |> Enum.sort() |> Enum.map(fn {_i, _j, a, b} -> {a, b} end)
  end

  defp sweep([], found), do: found

  defp sweep([a | rest], found) do
    found =
      rest
      |> Enum.take_while(&(&1.lat_min <= a.lat_max))
      |> Enum.reduce(found, fn b, found ->
        if meet?(a, b), do: [if(a.index < b.index, do: {a.index, b.index, a.timeline, b.timeline}, else: {b.index, a.index, b.timeline, a.timeline}) | found], else: found
      end)

    sweep(rest, found)
  end

  defp meet?(a, b), do: a.lon_min <= b.lon_max and b.lon_min <= a.lon_max and a.h_min <= b.h_max and b.h_min <= a.h_max

  # Widened by the limits, in degrees at the box's latitude (and a metre
  # more, for the straight lines between the points).
  defp box(%{points: points} = timeline, index, limits) do
    places = Enum.map(points, &elem(&1, 1))
    {lat_min, lat_max} = places |> Enum.map(& &1.lat) |> Enum.min_max()
    {lon_min, lon_max} = places |> Enum.map(& &1.lon) |> Enum.min_max()
    {h_min, h_max} = places |> Enum.map(& &1.h) |> Enum.min_max()
    across = limits.horizontal + 1.0
    dlat = across / 110_000
    nearest_pole = max(abs(lat_min), abs(lat_max)) + dlat
    # Near a pole a metre is too many degrees of longitude, and across the 180th meridian the box wraps: every longitude then.
    {lon_min, lon_max} =
      if nearest_pole > 89.9 or lon_max - lon_min > 180,
        do: {-540.0, 540.0},
        else: {lon_min - across / (111_320 * :math.cos(nearest_pole * :math.pi() / 180)), lon_max + across / (111_320 * :math.cos(nearest_pole * :math.pi() / 180))}

    %{
      index: index,
      timeline: timeline,
      lat_min: lat_min - dlat,
      lat_max: lat_max + dlat,
      lon_min: lon_min,
      lon_max: lon_max,
      h_min: h_min - limits.vertical,
      h_max: h_max + limits.vertical
    }
  end

  defp same_space?(a, b), do: Map.get(a, :airframe) == :sub == (Map.get(b, :airframe) == :sub)

  defp pair(a, b, limits) do
    from = max(first_ms(a), first_ms(b))
    to = max(last_ms(a), last_ms(b))
    plane = Geo.tangent_plane(elem(hd(a.points), 1))

    if to < from do
      []
    else
      times = Enum.uniq(Enum.sort(Enum.filter(Enum.map(a.points ++ b.points, &elem(&1, 0)), &(&1 >= from and &1 <= to)) ++ [from, to]))

      samples =
        times
        |> Enum.chunk_every(2, 1, :discard)
        |> Enum.flat_map(fn [t0, t1] -> Enum.to_list(t0..t1//@step_ms) end)
        |> Kernel.++([to])

      episodes(samples, a, b, plane, limits)
    end
  end

  # Each stretch of moments they are too close, as its closest moment. The
  # samples come in order: each timeline is walked once.
  defp episodes(samples, a, b, plane, limits) do
    {found, open, _ra, _rb} =
      Enum.reduce(samples, {[], nil, a.points, b.points}, fn t, {found, open, ra, rb} ->
        ra = advance(ra, t)
        rb = advance(rb, t)
        {pa, fly_a} = at(ra, t)
        {pb, fly_b} = at(rb, t)
        {an, ae} = Geo.to_tangent(plane, pa.lat, pa.lon)
        {bn, be} = Geo.to_tangent(plane, pb.lat, pb.lon)
        horizontal = :math.sqrt((an - bn) ** 2 + (ae - be) ** 2)
        vertical = abs(pa.h - pb.h)
        close? = (fly_a or fly_b) and horizontal < limits.horizontal and vertical < limits.vertical
        here = %{vehicles: {a.vehicle, b.vehicle}, at_ms: t, where: pa, horizontal: horizontal, vertical: vertical, missions: {mission_at(a, t), mission_at(b, t)}}

        cond do
          close? and (open == nil or apart(here) < apart(open)) -> {found, here, ra, rb}
          close? -> {found, open, ra, rb}
          open != nil -> {[open | found], nil, ra, rb}
          true -> {found, nil, ra, rb}
        end
      end)

    Enum.reverse(if open, do: [open | found], else: found)
  end

  defp apart(c), do: :math.sqrt(c.horizontal * c.horizontal + c.vertical * c.vertical)

  @doc false
  # Where timeline `points` put their vehicle at `t`, and whether it flies
  # then: straight and steady from each point to the next.
  @spec position([point()], integer()) :: {Geo.Location.t(), boolean()}
  def position(points, t), do: at(advance(points, t), t)

  # The timeline from the stretch that holds `t` on.
  defp advance([_, {t1, _, _} = next | rest], t) when t > t1, do: advance([next | rest], t)
  defp advance(points, _t), do: points

  defp first_ms(%{points: [{t, _, _} | _]}), do: t
  defp last_ms(%{points: points}), do: points |> List.last() |> elem(0)

  # Where the vehicle is at `t` (its timeline from the stretch that holds
  # it): before its first point at it, after its last at that.
  defp at([{t0, p0, f0} | _], t) when t <= t0, do: {p0, f0}

  defp at([{t0, p0, f0}, {t1, p1, f1} | _], t) when t <= t1 do
    fraction = if t1 == t0, do: 1.0, else: (t - t0) / (t1 - t0)
    {Dolphin.Geo.Shapes.along(p0, p1, fraction), f0 or f1}
  end

  defp at(points, _t) do
    {_, p, f} = List.last(points)
    {p, f}
  end

  # The mission the vehicle was flying (or last flew) at `t`.
  defp mission_at(%{missions: missions}, t) do
    missions |> Enum.filter(fn {start, _, _} -> start <= t end) |> List.last()
  end
end
