defmodule Dolphin.Geo.Area do
  @moduledoc """
  A circular area: a centre and a radius in metres (the report's `pos ^ r`).
  A location is inside when its geodesic distance from the centre, heights
  aside, is at most the radius (`Dolphin.Geo.contains?/2`).

      iex> Dolphin.Geo.Area.new(Dolphin.Geo.Location.new(38.43462, -8.86118), 2000)
      #Area<#Location<38.43462, -8.86118, 0.0 m>, 2000.0 m>
  """

  alias Dolphin.Geo.Location

  @enforce_keys [:center, :radius]
  defstruct [:center, :radius]

  @type t :: %__MODULE__{center: Location.t(), radius: float()}

  @doc "An area of `radius` metres (a non-negative number) around `center`."
  @spec new(Location.t(), number()) :: t()
  def new(%Location{} = center, radius) when is_number(radius) and radius >= 0, do: %__MODULE__{center: center, radius: radius / 1}

  def new(%Location{}, radius), do: raise(ArgumentError, "an area's radius must be a non-negative number of metres, got: #{inspect(radius)}")
  def new(center, _radius), do: raise(ArgumentError, "an area's center must be a location, got: #{inspect(center)}")

  defimpl Inspect do
    def inspect(%{center: center, radius: radius}, opts), do: "#Area<#{Inspect.inspect(center, opts)}, #{Location.format(radius, 3)} m>"
  end
end
