defmodule Dolphin.Geo.Location do
  @moduledoc """
  A WGS84 position: latitude and longitude in degrees, `h` the height above
  mean sea level in metres (the report's `location(lat, lon, h)`).

      iex> Dolphin.Geo.Location.new(40.444233, -7.375234, 820)
      #Location<40.444233, -7.375234, 820.0 m>

  Latitude must be within -90..90 and longitude within -180..180; anything
  else is a caller mistake (`ArgumentError`).
  """

  @enforce_keys [:lat, :lon]
  defstruct lat: 0.0, lon: 0.0, h: 0.0

  @type t :: %__MODULE__{lat: float(), lon: float(), h: float()}

  @doc "A location; `h` (metres above mean sea level) defaults to 0."
  @spec new(number(), number(), number()) :: t()
  def new(lat, lon, h \\ 0)

  def new(lat, lon, h) when is_number(lat) and is_number(lon) and is_number(h) do
    unless lat >= -90 and lat <= 90, do: raise(ArgumentError, "latitude must be within -90..90 degrees, got: #{inspect(lat)}")
    unless lon >= -180 and lon <= 180, do: raise(ArgumentError, "longitude must be within -180..180 degrees, got: #{inspect(lon)}")
    %__MODULE__{lat: lat / 1, lon: lon / 1, h: h / 1}
  end

  def new(lat, lon, h) do
    {name, value} = Enum.find([lat: lat, lon: lon, h: h], fn {_, v} -> not is_number(v) end)
    raise ArgumentError, "location #{name} must be a number, got: #{inspect(value)}"
  end

  @doc "The same latitude and longitude at height `h`."
  @spec at_height(t(), number()) :: t()
  def at_height(%__MODULE__{} = loc, h) when is_number(h), do: %{loc | h: h / 1}

  @doc false
  # A float in plain decimal notation (1200.0, not 1.2e3), at most `decimals` places.
  @spec format(number(), non_neg_integer()) :: String.t()
  def format(n, _decimals) when is_integer(n), do: Integer.to_string(n)
  def format(f, decimals) when is_float(f) and abs(f) < 1.0e15, do: :erlang.float_to_binary(f, [:compact, decimals: decimals])
  def format(f, _decimals), do: Float.to_string(f)

  defimpl Inspect do
    def inspect(%{lat: lat, lon: lon, h: h}, _opts), do: "#Location<#{Dolphin.Geo.Location.format(lat, 9)}, #{Dolphin.Geo.Location.format(lon, 9)}, #{Dolphin.Geo.Location.format(h, 3)} m>"
  end
end
