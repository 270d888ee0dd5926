defmodule Dolphin.Sim.World do
  @moduledoc """
  What simulated sensors sense: a world file (`--world FILE`, JSON), read by
  `read/1`, and the fields it makes (`smoke/3`, `water_temperature/3`,
  `range/3`). docs/simulator.md, "Sensors and the world", is the reference.

      {
        "fires": [{"lat": 40.4452, "lon": -7.3741, "radius_m": 40, "intensity": 0.9}],
        "wind": {"from_deg": 270, "speed_ms": 4},
        "water": {"base_celsius": 14, "fields": [{"lat": 38.43, "lon": -8.86, "radius_m": 300, "celsius": 19}]},
        "obstacles": [{"lat": 40.4447, "lon": -7.3750, "radius_m": 8, "height_m": 25}],
        "sensors": {"rate_hz": 4, "noise": 0.02}
      }

  Every key is optional (an empty object is a world with nothing in it);
  a fire needs `lat`, `lon`, `radius_m` (1..5000) and `intensity` (0..1);
  `wind` `from_deg` (0..360, where it blows from) and `speed_ms` (0..40);
  a water field `lat`, `lon`, `radius_m` and `celsius` (-5..40), over
  `base_celsius` (default 15); an obstacle `lat`, `lon`, `radius_m` (0.1..1000)
  and `height_m` (0.1..1000). `sensors` says how the simulated companions
  read the world: `rate_hz`, readings a second of vehicle time (0.1..50,
  default 2), and `noise`, the standard deviation added to each reading
  (0..100, default each sensor model's); `mix dolphin.sensors --rate` and
  `--noise` take precedence. A file that is not JSON, a key that is not
  one of these (with the nearest that is), a key missing, a value of the
  wrong type or out of range, is refused with the key's path and its line.

      iex> {:ok, w} = Dolphin.Sim.World.parse(~s({"fires": [{"lat": 40.0, "lon": -7.0, "radius_m": 50, "intensity": 1}]}))
      iex> Float.round(Dolphin.Sim.World.smoke(w, 40.0, -7.0), 2)
      1.0
      iex> Dolphin.Sim.World.parse(~s({"fires": [{"lat": 40.0, "lon": -7.0,\\n "radius": 50, "intensity": 1}]}))
      {:error, "line 2: fires[0]: unknown key \\"radius\\" (did you mean \\"radius_m\\"?); a fire takes lat, lon, radius_m, intensity"}
  """

  alias Dolphin.Geo

  defstruct fires: [], wind: %{from_deg: 0.0, speed_ms: 0.0}, water: %{base_celsius: 15.0, fields: []}, obstacles: [], sensing: %{}

  @type place :: %{lat: float(), lon: float(), radius_m: float()}
  @type t :: %__MODULE__{
          fires: [%{lat: float(), lon: float(), radius_m: float(), intensity: float()}],
          wind: %{from_deg: float(), speed_ms: float()},
          water: %{base_celsius: float(), fields: [%{lat: float(), lon: float(), radius_m: float(), celsius: float()}]},
          obstacles: [%{lat: float(), lon: float(), radius_m: float(), height_m: float()}],
          sensing: %{optional(:rate_hz) => float(), optional(:noise) => float()}
        }

  @place [{"lat", -90, 90}, {"lon", -180, 180}]
  @kinds %{
    "fires" => {"a fire", @place ++ [{"radius_m", 1, 5000}, {"intensity", 0, 1}]},
    "fields" => {"a water field", @place ++ [{"radius_m", 1, 50_000}, {"celsius", -5, 40}]},
    "obstacles" => {"an obstacle", @place ++ [{"radius_m", 0.1, 1000}, {"height_m", 0.1, 1000}]}
  }
  @wind [{"from_deg", 0, 360}, {"speed_ms", 0, 40}]
  @sensing [{"rate_hz", 0.1, 50}, {"noise", 0, 100}]

  # A range sensor's reach, metres: beyond it, it reads this.
  @range_max 40.0

  @doc "Reads a world file; an error says the file and what is wrong, at which line."
  @spec read(Path.t()) :: {:ok, t()} | {:error, String.t()}
  def read(path) do
    case File.read(path) do
      {:ok, text} -> with {:error, why} <- parse(text), do: {:error, "#{path}: #{why}"}
      {:error, why} -> {:error, "#{path}: cannot read it: #{:file.format_error(why)}"}
    end
  end

  @doc "Parses a world file's text (see the moduledoc)."
  @spec parse(String.t()) :: {:ok, t()} | {:error, String.t()}
  def parse(text) do
    with {:ok, json} <- Dolphin.JSONText.decode(text) do
      try do
        {:ok, world(json)}
      catch
        {:world, path, why} ->
          line = Map.get(Dolphin.JSONText.lines(text), path) || Map.get(Dolphin.JSONText.lines(text), Enum.drop(path, -1), 1)
          {:error, "line #{line}: #{why}"}
      end
    end
  end

  defp world(%{} = json) do
    keys!(json, [], ["fires", "wind", "water", "obstacles", "sensors"], "a world")

    %__MODULE__{
      fires: places(json, ["fires"]),
      wind: if(Map.has_key?(json, "wind"), do: numbers!(object!(json["wind"], ["wind"]), ["wind"], @wind, "the wind"), else: %{from_deg: 0.0, speed_ms: 0.0}),
      water: water(Map.get(json, "water", %{})),
      obstacles: places(json, ["obstacles"]),
      sensing: if(Map.has_key?(json, "sensors"), do: optional_numbers!(object!(json["sensors"], ["sensors"]), ["sensors"], @sensing, "a simulated sensor"), else: %{})
    }
  end

  defp world(other), do: fail([], "the world is a JSON object ({\"fires\": [...], ...}), got #{Dolphin.JSONText.kind(other)}")

  defp water(json) do
    json = object!(json, ["water"])
    keys!(json, ["water"], ["base_celsius", "fields"], "the water")
    base = Map.get(json, "base_celsius", 15)
    unless is_number(base) and base >= -5 and base <= 40, do: fail(["water", "base_celsius"], "must be a number -5..40, got #{Dolphin.JSONText.show(base)}")
    %{base_celsius: base * 1.0, fields: places(json, ["water", "fields"])}
  end

  defp places(json, path) do
    key = List.last(path)
    {what, spec} = Map.fetch!(@kinds, key)

    case Map.get(json, key, []) do
      list when is_list(list) -> list |> Enum.with_index() |> Enum.map(fn {item, i} -> numbers!(object!(item, path ++ [i]), path ++ [i], spec, what) end)
      other -> fail(Enum.drop(path, -1) ++ [key], "must be a list, got #{Dolphin.JSONText.kind(other)}")
    end
  end

  defp object!(%{} = map, _path), do: map
  defp object!(other, path), do: fail(path, "must be an object, got #{Dolphin.JSONText.kind(other)}")

  defp numbers!(map, path, spec, what) do
    names = Enum.map(spec, &elem(&1, 0))
    keys!(map, path, names, what)

    Map.new(spec, fn {key, low, high} ->
      case Map.fetch(map, key) do
        {:ok, n} when is_number(n) and n >= low and n <= high -> {String.to_atom(key), n * 1.0}
        {:ok, n} when is_number(n) -> fail(path ++ [key], "#{n} is out of range: #{what}'s #{key} is #{low}..#{high}")
        {:ok, other} -> fail(path ++ [key], "must be a number #{low}..#{high}, got #{Dolphin.JSONText.kind(other)}")
        :error -> fail(path, "#{key} is missing; #{what} takes #{Enum.join(names, ", ")}")
      end
    end)
  end

  # Numbers of which each may be left out.
  defp optional_numbers!(map, path, spec, what) do
    keys!(map, path, Enum.map(spec, &elem(&1, 0)), what)
    numbers!(map, path, Enum.filter(spec, &Map.has_key?(map, elem(&1, 0))), what)
  end

  defp keys!(map, path, allowed, what) do
    case Enum.find(Map.keys(map), &(&1 not in allowed)) do
      nil ->
        :ok

      key ->
        near = allowed |> Enum.filter(&(String.jaro_distance(&1, key) >= 0.8)) |> Enum.max_by(&String.jaro_distance(&1, key), fn -> nil end)
        hint = if near, do: " (did you mean #{inspect(near)}?)", else: ""
        fail(path ++ [key], "unknown key #{inspect(key)}#{hint}; #{what} takes #{Enum.join(allowed, ", ")}", path)
    end
  end

  defp fail(path, why, shown \\ nil), do: throw({:world, path, prefix(shown || path) <> why})

  defp prefix([]), do: ""
  defp prefix(path), do: show_path(path) <> ": "

  defp show_path(path) do
    Enum.map_join(path, fn
      i when is_integer(i) -> "[#{i}]"
      key -> ".#{key}"
    end)
    |> String.trim_leading(".")
  end

  # --- the fields ---

  @doc """
  The smoke a sensor reads at `lat`, `lon`: 0.0 (none) .. 1.0. Each fire is
  densest over its centre (its `intensity`, falling off over `radius_m`),
  and its plume drifts downwind, widening and thinning with distance; the
  fires add up, to at most 1.
  """
  @spec smoke(t(), float(), float()) :: float()
  def smoke(%__MODULE__{fires: []}, _lat, _lon), do: 0.0

  def smoke(%__MODULE__{fires: fires, wind: wind}, lat, lon) do
    toward = (wind.from_deg + 180) * :math.pi() / 180
    {wn, we} = {:math.cos(toward), :math.sin(toward)}

    fires
    |> Enum.map(fn f ->
      {n, e} = Geo.to_tangent(Geo.tangent_plane(%{lat: f.lat, lon: f.lon}), lat, lon)
      r = f.radius_m
      core = f.intensity * :math.exp(-((n * n + e * e) / (r * r)))
      # Downwind distance and distance off the plume's axis.
      x = n * wn + e * we
      y = abs(n * we - e * wn)

      plume =
        if wind.speed_ms > 0.5 and x > 0 do
          sigma = r + 0.15 * x
          f.intensity * (r / sigma) * :math.exp(-(y * y) / (sigma * sigma)) * :math.exp(-x / (300 + 50 * wind.speed_ms))
        else
          0.0
        end

      max(core, plume)
    end)
    |> Enum.sum()
    |> min(1.0)
  end

  @doc "The water's temperature (°C) at `lat`, `lon`: the base, and each field's toward its centre."
  @spec water_temperature(t(), float(), float()) :: float()
  def water_temperature(%__MODULE__{water: %{base_celsius: base, fields: fields}}, lat, lon) do
    Enum.reduce(fields, base, fn f, t ->
      d = Geo.distance(Geo.location(f.lat, f.lon), Geo.location(lat, lon))
      t + (f.celsius - base) * :math.exp(-(d * d) / (f.radius_m * f.radius_m))
    end)
  end

  @doc """
  What a range sensor reads (metres) at `lat`, `lon`, `h` (metres above
  sea level): the distance across to the nearest obstacle whose top is
  above `h` (its ground taken as `ground` m), at most #{@range_max} m.
  """
  @spec range(t(), float(), float(), float(), float()) :: float()
  def range(%__MODULE__{obstacles: obstacles}, lat, lon, h, ground) do
    here = Geo.location(lat, lon)

    obstacles
    |> Enum.filter(&(ground + &1.height_m > h))
    |> Enum.map(&max(Geo.distance(Geo.location(&1.lat, &1.lon), here) - &1.radius_m, 0.0))
    |> Enum.min(fn -> @range_max end)
    |> min(@range_max)
  end

  @doc "A range sensor's reach, metres."
  @spec range_max() :: float()
  def range_max, do: @range_max
end
