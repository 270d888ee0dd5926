defmodule Dolphin.Check.FleetFile do
  @moduledoc """
  The fleet a pre-flight check (`Dolphin.Check`, `mix dolphin.check --fleet
  FILE`) assumes: a JSON file such as

      {"vehicles": [
        {"id": 1, "type": "uav", "payloads": ["camera"], "battery": 1.0,
         "position": [40.444233, -7.375234, 820]},
        {"id": 2, "type": "uav", "battery": 0.6, "position": [40.4445, -7.3755, 820],
         "airborne": false}
      ]}

  Each vehicle: `id` (its MAVLink system id, 0..255, unique; required),
  `type` (default `"uav"`), `payloads` (default none), `battery` (the charge
  it starts with, 0.0..1.0; default 1.0), `position` (`[lat, lon, height
  above sea level]`, where it stands — its home; required), `airborne`
  (default false: on the ground).

      iex> Dolphin.Check.FleetFile.parse(~s({"vehicles":[{"id":3,"payloads":["camera"],"position":[41.0,-8.0,100]}]}))
      {:ok, [%{id: 3, type: :uav, payloads: [:camera], battery: 1.0, position: %Dolphin.Geo.Location{lat: 41.0, lon: -8.0, h: 100.0}, airborne?: false}]}
  """

  alias Dolphin.Check.FleetFileError
  alias Dolphin.Geo.Location

  @type vehicle :: %{id: 0..255, type: atom(), payloads: [atom()], battery: float(), position: Location.t(), airborne?: boolean()}

  @doc "Reads and parses a fleet file."
  @spec read(Path.t()) :: {:ok, [vehicle()]} | {:error, FleetFileError.t()}
  def read(path) do
    case File.read(path) do
      {:ok, text} -> with {:error, e} <- parse(text), do: {:error, %{e | file: path}}
      {:error, why} -> {:error, %FleetFileError{file: path, message: "cannot read it: #{:file.format_error(why)}"}}
    end
  end

  @doc "Parses a fleet file's text."
  @spec parse(String.t()) :: {:ok, [vehicle()]} | {:error, FleetFileError.t()}
  def parse(text) do
    case decode(text) do
      {:ok, %{"vehicles" => list}} when is_list(list) and list != [] -> vehicles(list)
      {:ok, _} -> error("expected an object with a non-empty \"vehicles\" list")
      {:error, why} -> error("not JSON (#{why})")
    end
  end

  defp decode(text) do
    {:ok, :jiffy.decode(text, [:return_maps])}
  catch
    :error, {pos, why} when is_integer(pos) -> {:error, "#{why} at byte #{pos}"}
    :throw, {:error, {pos, why}} -> {:error, "#{why} at byte #{pos}"}
  end

  defp vehicles(list) do
    list
    |> Enum.with_index(1)
    |> Enum.reduce_while({:ok, []}, fn {v, n}, {:ok, acc} ->
      case vehicle(v) do
        {:ok, vehicle} ->
          if Enum.any?(acc, &(&1.id == vehicle.id)),
            do: {:halt, error("vehicle ##{n}: id #{vehicle.id} is given twice")},
            else: {:cont, {:ok, [vehicle | acc]}}

        {:error, why} ->
          {:halt, error("vehicle ##{n}: #{why}")}
      end
    end)
    |> case do
      {:ok, acc} -> {:ok, Enum.reverse(acc)}
      error -> error
    end
  end

  defp vehicle(%{} = v) do
    with {:ok, id} <- field(v, "id", nil, &(is_integer(&1) and &1 in 0..255), "an integer system id 0..255"),
         {:ok, type} <- field(v, "type", "uav", &is_binary/1, "a string"),
         {:ok, type} <- known_atom(type, "type"),
         {:ok, payloads} <- field(v, "payloads", [], &(is_list(&1) and Enum.all?(&1, fn p -> is_binary(p) end)), "a list of strings"),
         {:ok, payloads} <- atoms(payloads),
         {:ok, battery} <- field(v, "battery", 1.0, &(is_number(&1) and &1 >= 0 and &1 <= 1), "a number from 0.0 to 1.0"),
         {:ok, [lat, lon, h]} <- field(v, "position", nil, &position?/1, "[latitude, longitude, height above sea level]"),
         {:ok, airborne} <- field(v, "airborne", false, &is_boolean/1, "true or false") do
      {:ok, %{id: id, type: type, payloads: Enum.sort(payloads), battery: battery * 1.0, position: %Location{lat: lat * 1.0, lon: lon * 1.0, h: h * 1.0}, airborne?: airborne}}
    end
  end

  defp vehicle(other), do: {:error, "expected an object, got #{:jiffy.encode(other)}"}

  defp position?([lat, lon, h]) when is_number(lat) and is_number(lon) and is_number(h), do: lat >= -90 and lat <= 90 and lon >= -180 and lon <= 180
  defp position?(_), do: false

  defp field(v, key, default, ok?, what) do
    case Map.fetch(v, key) do
      :error when default == nil -> {:error, "\"#{key}\" is missing (#{what})"}
      :error -> {:ok, default}
      {:ok, value} -> if ok?.(value), do: {:ok, value}, else: {:error, "\"#{key}\" must be #{what}, got #{:jiffy.encode(value)}"}
    end
  end

  # Types and payloads are atoms a script names (`pick(type: :uav)`): a name
  # no code knows cannot be asked for, and is refused rather than made an atom.
  defp known_atom(name, what) do
    {:ok, String.to_existing_atom(name)}
  rescue
    ArgumentError -> {:error, "unknown #{what} #{inspect(name)}"}
  end

  defp atoms(names) do
    Enum.reduce_while(names, {:ok, []}, fn name, {:ok, acc} ->
      case known_atom(name, "payload") do
        {:ok, atom} -> {:cont, {:ok, [atom | acc]}}
        error -> {:halt, error}
      end
    end)
  end

  defp error(message), do: {:error, %FleetFileError{message: message}}
end
