defmodule Dolphin.Geo.Polygon do
  @moduledoc """
  A polygon on the ground: its corners, in order, as locations (heights are
  not part of it). Made with `Dolphin.Geo.Shapes.polygon/1`, which refuses
  fewer than three corners or edges that cross; `Dolphin.Geo.Shapes` says
  whether a point is in it and where a straight leg enters or leaves it.
  """

  @enforce_keys [:points]
  defstruct [:points]

  @type t :: %__MODULE__{points: [Dolphin.Geo.Location.t()]}

  defimpl Inspect do
    def inspect(%{points: points}, _opts), do: "#Polygon<#{length(points)} corners>"
  end
end
