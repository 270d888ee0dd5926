defmodule Dolphin.Mission.Survey do
  @moduledoc """
  The lawnmower of `survey_area`: the waypoints that sweep a rectangle.

  The rectangle has one corner at the base point and lies to its
  `direction` (`:north_east`: north and east of it). `length` is its
  north–south extent, `width` its east–west extent. The passes run
  north–south over the whole length ("vertical passes", as the report puts
  it) and step across the width:

    * `n = ceil(width / spacing)` passes (at least one), evenly spread:
      pass `k` (from 0) lies `(k + ½) · width / n` metres from the base's
      meridian. Neighbouring passes are `width / n ≤ spacing` apart and the
      outer ones `width / 2n ≤ spacing / 2` from the edges, so every point
      of the rectangle is within `spacing / 2` of a pass — think of `spacing`
      as the swath of the sensor.
    * Each pass is two waypoints, its ends on the rectangle's north and south
      edges; the first pass starts on the base's edge, and the passes
      alternate direction. So a survey is `2n` mission items.
    * Offsets are azimuthal equidistant metres around the base
      (`Dolphin.Geo.offset/4`), at the base's height.

  The report's Listing 3 (`survey_area 3000, 10000, 500, :north_east`) is 20
  passes of 3 km, 500 m apart, the first 250 m east of the base: 40 items.

      iex> base = Dolphin.Geo.location(40.444233, -7.375234, 1200)
      iex> Dolphin.Mission.Survey.item_count(10000, 500)
      40
      iex> [first, second | _] = Dolphin.Mission.Survey.waypoints(base, 3000, 10000, 500, :north_east)
      iex> {n, e} = Dolphin.Geo.ne_offset(base, first)
      iex> {round(n), round(e)}
      {0, 250}
      iex> {n, e} = Dolphin.Geo.ne_offset(base, second)
      iex> {round(n), round(e)}
      {3000, 250}
  """

  alias Dolphin.Geo
  alias Dolphin.Geo.Location

  @type direction :: :north_west | :north_east | :south_west | :south_east

  @doc "The number of passes sweeping `width` metres at most `spacing` apart."
  @spec pass_count(number(), number()) :: pos_integer()
  def pass_count(width, spacing) when width > 0 and spacing > 0 do
    # The tolerance keeps 10000 / 500 at 20 passes whatever the float rounding.
    max(1, ceil(width / spacing - 1.0e-9))
  end

  @doc "The number of mission items of a survey: two per pass."
  @spec item_count(number(), number()) :: pos_integer()
  def item_count(width, spacing), do: 2 * pass_count(width, spacing)

  @doc """
  The passes as `{north, east}` metre offsets from the base: a list of
  `{start, end}` pairs in flying order.
  """
  @spec passes(number(), number(), number(), direction()) :: [{{float(), float()}, {float(), float()}}]
  def passes(length, width, spacing, direction) do
    {sn, se} = signs(direction)
    n = pass_count(width, spacing)
    step = width / n

    for k <- 0..(n - 1) do
      east = se * (k + 0.5) * step
      {from, to} = if rem(k, 2) == 0, do: {0.0, sn * length / 1}, else: {sn * length / 1, 0.0}
      {{from, east}, {to, east}}
    end
  end

  @doc "The survey's waypoints, in flying order, at the height of `base`."
  @spec waypoints(Location.t(), number(), number(), number(), direction()) :: [Location.t()]
  def waypoints(%Location{} = base, length, width, spacing, direction) do
    for {{n1, e1}, {n2, e2}} <- passes(length, width, spacing, direction), {n, e} <- [{n1, e1}, {n2, e2}] do
      Geo.offset(base, n, e, 0)
    end
  end

  defp signs(:north_east), do: {1, 1}
  defp signs(:north_west), do: {1, -1}
  defp signs(:south_east), do: {-1, 1}
  defp signs(:south_west), do: {-1, -1}
end
