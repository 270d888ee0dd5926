defmodule Dolphin.Check.FleetFile do
  @moduledoc """
  The fleet a pre-flight check (`Dolphin.Check`, `mix dolphin.check --fleet
  FILE`) assumes, and what a run (`mix dolphin.run --fleet FILE`, `mix
  dolphin.console --fleet FILE`) adds to the vehicles it hears: a JSON file
  such as

      {"vehicles": [
        {"id": 1, "airframe": "copter", "payloads": ["camera"], "battery": 1.0,
         "position": [40.444233, -7.375234, 820]},
        {"id": 2, "type": "uav", "battery": 0.6, "position": [40.4445, -7.3755, 820],
         "airborne": false},
        {"id": 7, "airframe": "sub", "payloads": ["sidescan"], "position": [38.39, -8.81, 0]}
      ]}

  Each vehicle: `id` (its MAVLink system id, 0..255, unique; required),
  `type` (`"uav"`, `"ugv"`, `"usv"`, `"uuv"` or `"other"`, as `pick(type:
  ...)` names them), `airframe` (`"copter"`, `"plane"`, `"quadplane"`,
  `"rover"`, `"boat"` or `"sub"`, as `pick(airframe: ...)` names them) — each
  defaults from the other (a `"sub"` is a `"uuv"`; a `"usv"` a `"boat"`), a
  uav copter when neither is given —, `payloads` (names such as `"camera"`,
  `"thermal_camera"` or `"sidescan"`, as `pick(payload: ...)` writes them;
  default none), `battery` (the charge it starts with, 0.0..1.0; default
  1.0), `position` (`[lat, lon, height above sea level]`, where it stands —
  its home; required by a check), `airborne` (default false: on the ground),
  `sensors` (with `--sim` or `--sitl`: the simulator's sensors its companion
  computer carries, `"smoke"`, `"water_temp"`, `"range"`, as
  `--sim copter:2+smoke` gives them; default none).

  In a run, a vehicle's type, airframe and position are what it reports: the
  file gives it only its payloads — those it cannot announce over MAVLink
  (a side-scan sonar, a smoke sensor) — by system id, and a vehicle needs
  no position there (`read(path, position: :optional)`: `nil` when none).

  A file that cannot be used is an error naming every problem in it: each
  field of each vehicle that is wrong, or where the JSON text breaks (byte
  and line).

      iex> Dolphin.Check.FleetFile.parse(~s({"vehicles":[{"id":3,"payloads":["camera"],"position":[41.0,-8.0,100]}]}))
      {:ok, [%{id: 3, type: :uav, airframe: :copter, payloads: [:camera], battery: 1.0, position: %Dolphin.Geo.Location{lat: 41.0, lon: -8.0, h: 100.0}, airborne?: false, sensors: []}]}
      iex> {:ok, [v]} = Dolphin.Check.FleetFile.parse(~s({"vehicles":[{"id":4,"airframe":"sub","payloads":["sidescan"],"position":[38.4,-8.8,0]}]}))
      iex> {v.type, v.airframe, v.payloads}
      {:uuv, :sub, [:sidescan]}
      iex> {:error, e} = Dolphin.Check.FleetFile.parse(~s({"vehicles":[{"id":300,"type":"boat","position":[41.0,-8.0,100]},{"id":5,"type":"usv","airframe":"plane","position":[41.0,-8.0,0]}]}))
      iex> e.problems
      [~s<vehicle #1: "id" must be an integer system id 0..255, got 300>, ~s<vehicle #1: unknown type "boat" (one of uav, ugv, usv, uuv, other)>, ~s<vehicle #2: airframe "plane" is a uav, not a usv>]
  """

  alias Dolphin.Check.FleetFileError
  alias Dolphin.Geo.Location
  alias Dolphin.Vehicles.View
  alias Dolphin.MAVLink.{JSON, JSONError}

  # The vehicle classes a pick asks for (Dolphin.Vehicles.View.class/1), by
  # their names in the file: written out, so that no name read from a file
  # has to exist as an atom already.
  @types [{"uav", :uav}, {"ugv", :ugv}, {"usv", :usv}, {"uuv", :uuv}, {"other", :other}]
  @airframes for a <- View.airframes(), do: {Atom.to_string(a), a}
  @payload_name ~r/^[a-z][a-z0-9_]{0,63}$/

  @type vehicle :: %{id: 0..255, type: atom(), airframe: View.airframe() | nil, payloads: [atom()], battery: float(), position: Location.t() | nil, airborne?: boolean(), sensors: [atom()]}

  @doc """
  Reads and parses a fleet file. Option `position: :optional` (a run's
  reading) lets a vehicle have no position; by default (a check's) each
  must have one.
  """
  @spec read(Path.t(), keyword()) :: {:ok, [vehicle()]} | {:error, FleetFileError.t()}
  def read(path, opts \\ []) do
    result =
      case File.read(path) do
        {:ok, text} -> parse(text, opts)
        {:error, why} -> error(["cannot read it: #{:file.format_error(why)}"])
      end

    with {:error, e} <- result, do: {:error, %{e | file: path}}
  end

  @doc "Parses a fleet file's text (options as `read/2`'s); an error lists every problem found."
  @spec parse(String.t(), keyword()) :: {:ok, [vehicle()]} | {:error, FleetFileError.t()}
  def parse(text, opts \\ []) do
    position = if Keyword.get(opts, :position, :required) == :optional, do: nil, else: :required

    case JSON.decode(text) do
      {:ok, %{"vehicles" => list}} when is_list(list) and list != [] -> vehicles(list, position)
      {:ok, _} -> error(["expected an object with a non-empty \"vehicles\" list, such as {\"vehicles\": [{\"id\": 1, \"position\": [40.44, -7.37, 820]}]}"])
      {:error, e} -> error(["not valid JSON: " <> json_problem(e, text)])
    end
  end

  # Where the text breaks, in the words of someone editing the file.
  defp json_problem(%JSONError{position: at} = e, text) do
    lines = text |> binary_part(0, at) |> String.split("\n")
    where = "byte #{at}, line #{length(lines)}, column #{byte_size(List.last(lines)) + 1}"

    cond do
      String.trim(text) == "" -> "the file is empty"
      at >= byte_size(text) -> "the text ends in the middle of a value (#{where})"
      # The decoder's own words, its position given as above.
      true -> "#{e |> Exception.message() |> String.replace(~r/ at byte \d+,/, ",")} (#{where})"
    end
  end

  defp vehicles(list, position) do
    parsed = list |> Enum.with_index(1) |> Enum.map(fn {v, n} -> {n, v, vehicle(v, position)} end)
    problems = for {n, _v, {:error, whys}} <- parsed, why <- whys, do: {n, "vehicle ##{n}: #{why}"}

    # An id given twice is a problem of the later vehicle, whatever else is wrong with either.
    twice =
      parsed
      |> Enum.filter(fn {_n, v, _} -> is_map(v) and is_integer(v["id"]) and v["id"] in 0..255 end)
      |> Enum.group_by(fn {_n, v, _} -> v["id"] end)
      |> Enum.flat_map(fn {id, [_first | again]} -> for {n, _, _} <- again, do: {n, "vehicle ##{n}: id #{id} is given twice"} end)

    case problems ++ twice do
      [] -> {:ok, for({_n, _v, {:ok, vehicle}} <- parsed, do: vehicle)}
      # By vehicle, in the order found (the sort is stable).
      all -> all |> Enum.sort_by(&elem(&1, 0)) |> Enum.map(&elem(&1, 1)) |> error()
    end
  end

  defp vehicle(%{} = v, position) do
    fields = [
      id: field(v, "id", :required, &(is_integer(&1) and &1 in 0..255), "an integer system id 0..255"),
      type: v |> field("type", nil, &is_binary/1, "a string") |> and_then(&type/1),
      airframe: v |> field("airframe", nil, &is_binary/1, "a string") |> and_then(&airframe/1),
      payloads: v |> field("payloads", [], &(is_list(&1) and Enum.all?(&1, fn p -> is_binary(p) end)), "a list of strings") |> and_then(&payloads/1),
      battery: field(v, "battery", 1.0, &(is_number(&1) and &1 >= 0 and &1 <= 1), "a number from 0.0 to 1.0"),
      position: field(v, "position", position, &(position?(&1) or (&1 == nil and position == nil)), "[latitude, longitude, height above sea level], latitude -90..90, longitude -180..180"),
      airborne: field(v, "airborne", false, &is_boolean/1, "true or false"),
      sensors: v |> field("sensors", [], &(is_list(&1) and Enum.all?(&1, fn p -> is_binary(p) end)), "a list of strings") |> and_then(&sensors/1)
    ]

    fields = fields ++ [kind: kind(fields[:type], fields[:airframe])]

    case for({_k, {:error, why}} <- fields, do: why) do
      [] ->
        f = Map.new(fields, fn {k, {:ok, value}} -> {k, value} end)
        {type, airframe} = f.kind
        {:ok, %{id: f.id, type: type, airframe: airframe, payloads: Enum.sort(f.payloads), battery: f.battery * 1.0, position: location(f.position), airborne?: f.airborne, sensors: f.sensors}}

      whys ->
        {:error, whys}
    end
  end

  defp vehicle(other, _position), do: {:error, ["expected an object, got #{shown(other)}"]}

  defp location(nil), do: nil
  defp location([lat, lon, h]), do: %Location{lat: lat * 1.0, lon: lon * 1.0, h: h * 1.0}

  defp position?([lat, lon, h]) when is_number(lat) and is_number(lon) and is_number(h), do: lat >= -90 and lat <= 90 and lon >= -180 and lon <= 180
  defp position?(_), do: false

  defp field(v, key, default, ok?, what) do
    case Map.fetch(v, key) do
      :error when default == :required -> {:error, "\"#{key}\" is missing (#{what})"}
      :error -> {:ok, default}
      {:ok, value} -> if ok?.(value), do: {:ok, value}, else: {:error, "\"#{key}\" must be #{what}, got #{shown(value)}"}
    end
  end

  defp and_then({:ok, value}, fun), do: fun.(value)
  defp and_then(error, _fun), do: error

  defp type(nil), do: {:ok, nil}

  defp type(name) do
    case List.keyfind(@types, name, 0) do
      {_, type} -> {:ok, type}
      nil -> {:error, "unknown type #{inspect(name)} (one of #{@types |> Enum.map(&elem(&1, 0)) |> Enum.join(", ")})"}
    end
  end

  defp airframe(nil), do: {:ok, nil}

  defp airframe(name) do
    case List.keyfind(@airframes, name, 0) do
      {_, airframe} -> {:ok, airframe}
      nil -> {:error, "unknown airframe #{inspect(name)} (one of #{@airframes |> Enum.map(&elem(&1, 0)) |> Enum.join(", ")})"}
    end
  end

  # The type and airframe, each the other's default (a uav copter when neither is given).
  defp kind({:ok, nil}, {:ok, nil}), do: {:ok, {:uav, :copter}}
  defp kind({:ok, type}, {:ok, nil}), do: {:ok, {type, View.stand_in_airframe(type)}}
  defp kind({:ok, nil}, {:ok, airframe}), do: {:ok, {View.airframe_class(airframe), airframe}}

  defp kind({:ok, type}, {:ok, airframe}) do
    if View.airframe_class(airframe) == type,
      do: {:ok, {type, airframe}},
      else: {:error, "airframe \"#{airframe}\" is a #{View.airframe_class(airframe)}, not a #{type}"}
  end

  # A problem with either is said by its own field.
  defp kind(_type, _airframe), do: {:ok, nil}

  # The simulator's sensor models (Dolphin.Sim.Companion) a simulated vehicle carries.
  defp sensors(names) do
    models = Enum.map(Dolphin.Sim.Companion.models(), &Atom.to_string/1)

    case Enum.reject(names, &(&1 in models)) do
      [] -> {:ok, names |> Enum.uniq() |> Enum.map(&String.to_existing_atom/1)}
      bad -> {:error, "no simulated sensor #{Enum.map_join(bad, ", ", &inspect/1)} (the simulator's sensors are #{Enum.join(models, ", ")})"}
    end
  end

  # A payload is whatever the operator's vehicles carry: any name a script
  # could write as an atom (`pick(payload: :thermal_camera)`). The file is the
  # operator's own, read once per check, so its few names may become atoms.
  defp payloads(names) do
    case Enum.reject(names, &(&1 =~ @payload_name)) do
      [] -> {:ok, names |> Enum.uniq() |> Enum.map(&String.to_atom/1)}
      bad -> {:error, "payload names are lower-case letters, digits and _ (as in \"thermal_camera\"), got #{Enum.map_join(bad, ", ", &inspect/1)}"}
    end
  end

  defp shown(value) when is_binary(value), do: inspect(value)
  defp shown(value), do: value |> JSON.encode() |> IO.iodata_to_binary()

  defp error(problems), do: {:error, FleetFileError.new(problems)}
end
