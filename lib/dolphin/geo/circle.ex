defmodule Dolphin.Geo.Circle do
  @moduledoc """
  A circle on the ground: its centre (a location; its height is not part of
  it) and its radius in metres. Made with `Dolphin.Geo.Shapes.circle/2`.
  """

  @enforce_keys [:centre, :radius]
  defstruct [:centre, :radius]

  @type t :: %__MODULE__{centre: Dolphin.Geo.Location.t(), radius: float()}

  defimpl Inspect do
    def inspect(%{centre: c, radius: r}, _opts), do: "#Circle<#{c.lat}, #{c.lon}, #{r} m>"
  end
end
