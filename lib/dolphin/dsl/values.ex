defmodule Dolphin.DSL.Values do
  @moduledoc """
  The values of the script language (docs/language.md, "Values"): positions, areas,
  units, distances. Scripts import this module.

  | Dolphin (Groovy) | here |
  |---|---|
  | `location(lat, lon, h)` | `location(lat, lon, h \\\\ 0)`: a `Dolphin.Geo.Location`, `h` metres above mean sea level |
  | `pos ^ r`, `area(pos, r)` | `area(center, radius)`: a `Dolphin.Geo.Area` |
  | `10.minutes`, `30.seconds`, `2.km` | `minutes(10)`, `seconds(30)`, `hours/1`, `days/1`: durations in milliseconds (integers); `km(2)`, `meters/1`: metres |
  | | `percent(30)` is `0.3`; `degrees(15)` is `15.0` (angles are degrees throughout) |
  | `p.distanceTo(q)`, `near`, `contains` | `distance(p, q)` (metres, geodesic on WGS84, heights aside), `near?(p, q, r)`, `contains?(area, p)` |

      iex> import Dolphin.DSL.Values
      iex> minutes(10)
      600000
      iex> seconds(1.5)
      1500
      iex> km(2)
      2000
      iex> percent(30)
      0.3
      iex> comporta = area(location(38.43462, -8.86118), km(2))
      iex> contains?(comporta, location(38.44, -8.86))
      true
      iex> near?(location(38.43462, -8.86118), location(38.44, -8.86), 500)
      false

  The mission commands take seconds, as in the report (`delay 30`), not
  these millisecond durations.
  """

  alias Dolphin.Geo

  @doc """
  A WGS84 position: latitude and longitude in degrees, `h` in metres above
  mean sea level (default 0), as missions take heights. Raises
  `ArgumentError` for a latitude or longitude out of range.

      iex> p = location(40.444233, -7.375234, 820)
      iex> {p.lat, p.lon, p.h}
      {40.444233, -7.375234, 820.0}
  """
  @spec location(number(), number(), number()) :: Geo.Location.t()
  def location(lat, lon, h \\ 0), do: Geo.location(lat, lon, h)

  @doc """
  A circular area of `radius` metres around `center` (for `contains?/2` and
  `pick(region: ...)`).

      iex> zone = area(location(38.43462, -8.86118), km(2))
      iex> zone.radius
      2000.0
  """
  @spec area(Geo.Location.t(), number()) :: Geo.Area.t()
  def area(center, radius), do: Geo.area(center, radius)

  @doc """
  A polygon zone of a fence (`Dolphin.DSL.Fence`): its corners, in order
  (at least three; its edges must not cross).

      exclude polygon([location(38.4380, -8.8620, 0), location(38.4380, -8.8590, 0), location(38.4395, -8.8600, 0)])
  """
  @spec polygon([Dolphin.Geo.Location.t()]) :: Dolphin.Geo.Polygon.t()
  def polygon(corners), do: ok!(Dolphin.Geo.Shapes.polygon(corners))

  @doc """
  A circular zone of a fence (`Dolphin.DSL.Fence`): its centre and radius in metres.

      include circle(location(38.43462, -8.86118, 0), 800)
  """
  @spec circle(Dolphin.Geo.Location.t(), number()) :: Dolphin.Geo.Circle.t()
  def circle(centre, radius), do: ok!(Dolphin.Geo.Shapes.circle(centre, radius))

  defp ok!({:ok, value}), do: value
  defp ok!({:error, why}), do: raise(ArgumentError, why)

  @doc """
  `n` days, in milliseconds.

      iex> days(1)
      86400000
  """
  @spec days(number()) :: integer()
  def days(n), do: ms(n, 86_400_000, :days)

  @doc """
  `n` hours, in milliseconds.

      iex> hours(2)
      7200000
  """
  @spec hours(number()) :: integer()
  def hours(n), do: ms(n, 3_600_000, :hours)

  @doc """
  `n` minutes, in milliseconds (what `idle`, `during`, `pause` and `pick`'s
  timeout take).

      iex> minutes(10)
      600000
  """
  @spec minutes(number()) :: integer()
  def minutes(n), do: ms(n, 60_000, :minutes)

  @doc """
  `n` seconds, in milliseconds (rounded to the millisecond). Mission
  commands take plain seconds instead (`delay 30`).

      iex> seconds(1.5)
      1500
  """
  @spec seconds(number()) :: integer()
  def seconds(n), do: ms(n, 1000, :seconds)

  defp ms(n, scale, _unit) when is_integer(n), do: n * scale
  defp ms(n, scale, _unit) when is_float(n), do: round(n * scale)
  defp ms(other, _scale, unit), do: raise(ArgumentError, "#{unit}/1 takes a number, got: #{inspect(other)}")

  @doc """
  `n` kilometres, in metres.

      iex> km(2)
      2000
  """
  @spec km(number()) :: number()
  def km(n) when is_number(n), do: n * 1000
  def km(other), do: raise(ArgumentError, "km/1 takes a number, got: #{inspect(other)}")

  @doc """
  `n` metres (distances are metres throughout; this only reads well).

      iex> meters(500)
      500
  """
  @spec meters(number()) :: number()
  def meters(n) when is_number(n), do: n
  def meters(other), do: raise(ArgumentError, "meters/1 takes a number, got: #{inspect(other)}")

  @doc """
  `n` percent, as a fraction, the unit of `battery/1`.

      iex> percent(30)
      0.3
  """
  @spec percent(number()) :: float()
  def percent(n) when is_number(n), do: n / 100
  def percent(other), do: raise(ArgumentError, "percent/1 takes a number, got: #{inspect(other)}")

  @doc """
  `n` degrees, as a float: angles (yaw, pitch, headings) are degrees
  throughout.

      iex> degrees(15)
      15.0
  """
  @spec degrees(number()) :: float()
  def degrees(n) when is_number(n), do: n / 1
  def degrees(other), do: raise(ArgumentError, "degrees/1 takes a number, got: #{inspect(other)}")

  # An unknown position (nil: `position(v)` before the vehicle reports one)
  # gives an unknown answer, which a condition treats as not met (see
  # Dolphin.DSL, "Unknown values"), rather than an error that fails the task.

  @doc """
  The geodesic distance in metres between two locations, on WGS84, heights
  aside (see `Dolphin.Geo.distance/2`); nil if either is nil (unknown).

      iex> round(distance(location(40.0, -7.0), location(40.001, -7.0)))
      111
  """
  @spec distance(Geo.Location.t() | nil, Geo.Location.t() | nil) :: float() | nil
  def distance(p, q) when p == nil or q == nil, do: nil
  def distance(p, q), do: Geo.distance(p, q)

  @doc """
  Whether `q` is within `radius` metres of `p`; nil if either location is nil (unknown).

      iex> near?(location(40.0, -7.0), location(40.001, -7.0), 200)
      true
  """
  @spec near?(Geo.Location.t() | nil, Geo.Location.t() | nil, number()) :: boolean() | nil
  def near?(p, q, _radius) when p == nil or q == nil, do: nil
  def near?(p, q, radius), do: Geo.near?(p, q, radius)

  @doc """
  Whether location `p` lies within `area`; nil if `p` is nil (unknown).

      iex> contains?(area(location(40.0, -7.0), 100), location(40.01, -7.0))
      false
  """
  @spec contains?(Geo.Area.t(), Geo.Location.t() | nil) :: boolean() | nil
  def contains?(_area, nil), do: nil
  def contains?(area, p), do: Geo.contains?(area, p)
end
