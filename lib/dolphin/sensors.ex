defmodule Dolphin.Sensors do
  @moduledoc """
  Sensors as declared data (docs/language.md, "Sensors"): a script names
  where a reading comes from — a NAMED_VALUE_FLOAT / NAMED_VALUE_INT by
  name, or any numeric field of any message of the dialect — and reads it
  like `battery/1`.

      iex> {:ok, smoke} = Dolphin.Sensors.new(:smoke, from: {:named_value, "SMOKE"}, stale_after: 5_000)
      iex> smoke.source
      {:named_value, "SMOKE"}
      iex> {:ok, water} = Dolphin.Sensors.new(:water_temp, from: {:message, :SCALED_PRESSURE2, :temperature}, scale: 0.01, unit: :celsius)
      iex> Dolphin.Sensors.describe_source(water.source)
      "SCALED_PRESSURE2.temperature"
      iex> Dolphin.Sensors.new(:water_temp, from: {:message, :SCALED_PRESURE2, :temperature})
      {:error, "sensor :water_temp: no message SCALED_PRESURE2 in the dialect; did you mean SCALED_PRESSURE2, SCALED_PRESSURE, SCALED_PRESSURE3?"}

  The vehicles layer folds readings into each vehicle's view
  (`Dolphin.Sensors.Readings`, `Dolphin.Vehicles.watch_sensors/1`); a
  reading's value is `value/2` of its sensor.
  """

  alias Dolphin.Sensors.Sensor

  @options [:from, :scale, :offset, :unit, :stale_after, :keep]
  @numeric [:uint8_t, :int8_t, :uint16_t, :int16_t, :uint32_t, :int32_t, :uint64_t, :int64_t, :float, :double, :uint8, :int8, :uint16, :int16, :uint32, :int32, :uint64, :int64]

  @doc """
  A sensor named `name` from its declaration's options: `from:` (required:
  `{:named_value, "NAME"}`, at most 10 characters as MAVLink carries them,
  or `{:message, :MESSAGE_NAME, :field}`, a numeric field of a message of
  the dialect), `scale:` and `offset:` (numbers: value = raw × scale +
  offset), `unit:` (an atom), `stale_after:` and `keep:` (clock ms, more
  than 0). Says what is wrong, with the names that were near, otherwise.
  """
  @spec new(atom(), keyword()) :: {:ok, Sensor.t()} | {:error, String.t()}
  def new(name, opts) when is_atom(name) and is_list(opts) do
    with :ok <- known_options(name, opts),
         {:ok, source, unit} <- source(name, Keyword.get(opts, :from)),
         {:ok, scale} <- number(name, opts, :scale, 1.0),
         {:ok, offset} <- number(name, opts, :offset, 0.0),
         {:ok, stale_after} <- duration(name, opts, :stale_after, nil),
         {:ok, keep} <- duration(name, opts, :keep, 60_000),
         {:ok, unit} <- unit(name, Keyword.get(opts, :unit, unit)) do
      {:ok, %Sensor{name: name, source: source, scale: scale, offset: offset, unit: unit, stale_after: stale_after, keep: keep}}
    end
  end

  def new(name, _opts) when not is_atom(name), do: {:error, "a sensor's name is an atom (sensor :smoke, from: ...), got: #{inspect(name)}"}
  def new(name, opts), do: {:error, "sensor #{inspect(name)}: its options are a keyword list (from: ...), got: #{inspect(opts)}"}

  defp known_options(name, opts) do
    case Enum.find(opts, fn {k, _} -> k not in @options end) do
      nil -> if Keyword.has_key?(opts, :from), do: :ok, else: {:error, "sensor #{inspect(name)} needs from: {:named_value, \"NAME\"} or from: {:message, :MESSAGE, :field}"}
      {k, _} -> {:error, "sensor #{inspect(name)}: unknown option #{inspect(k)}#{near(Atom.to_string(k), Enum.map(@options, &Atom.to_string/1), &":#{&1}")}; options are #{inspect(@options)}"}
    end
  end

  defp source(name, {:named_value, value_name}) when is_binary(value_name) do
    cond do
      value_name == "" or byte_size(value_name) > 10 -> {:error, "sensor #{inspect(name)}: a named value's name has 1 to 10 characters (NAMED_VALUE_FLOAT carries 10), got: #{inspect(value_name)}"}
      not String.printable?(value_name) or value_name != String.trim(value_name) -> {:error, "sensor #{inspect(name)}: a named value's name is printable, without spaces at its ends, got: #{inspect(value_name)}"}
      true -> {:ok, {:named_value, value_name}, nil}
    end
  end

  defp source(name, {:message, message, field}) when is_atom(message) and is_atom(field) do
    text = Atom.to_string(message)

    case Dolphin.MAVLink.UserDialect.message_module(text) do
      nil ->
        {:error, "sensor #{inspect(name)}: no message #{text} in the dialect#{near(text, message_names(), & &1)}"}

      module ->
        fields = module.__mavlink__(:fields)

        case Enum.find(fields, &(&1.name == field)) do
          nil ->
            names = Enum.map(fields, &Atom.to_string(&1.name))
            {:error, "sensor #{inspect(name)}: #{text} has no field #{inspect(field)}#{near(Atom.to_string(field), names, &":#{&1}")}; its fields: #{Enum.join(names, ", ")}"}

          %{type: type, array_length: length} when length != nil or type not in @numeric ->
            {:error, "sensor #{inspect(name)}: #{text}.#{field} is not a number (#{type}#{if length, do: "[#{length}]"}): a sensor reads one numeric field"}

          %{units: units} ->
            {:ok, {:message, module, field}, units && String.to_atom(units)}
        end
    end
  end

  defp source(name, other),
    do: {:error, "sensor #{inspect(name)}: from: takes {:named_value, \"NAME\"} or {:message, :MESSAGE_NAME, :field}, got: #{inspect(other)}"}

  defp number(name, opts, key, default) do
    case Keyword.get(opts, key, default) do
      n when is_number(n) -> {:ok, n}
      other -> {:error, "sensor #{inspect(name)}: #{key}: takes a number, got: #{inspect(other)}"}
    end
  end

  defp duration(name, opts, key, default) do
    case Keyword.get(opts, key, default) do
      ^default -> {:ok, default}
      ms when is_integer(ms) and ms > 0 -> {:ok, ms}
      other -> {:error, "sensor #{inspect(name)}: #{key}: takes a duration (seconds(5), milliseconds as a positive integer), got: #{inspect(other)}"}
    end
  end

  defp unit(_name, unit) when is_atom(unit), do: {:ok, unit}
  defp unit(name, other), do: {:error, "sensor #{inspect(name)}: unit: takes an atom (:celsius, :cm, ...), got: #{inspect(other)}"}

  defp message_names, do: Enum.map(Dolphin.MAVLink.UserDialect.messages(), & &1.__mavlink__(:name))

  # The names nearest `word`, as "; did you mean A, B?" (empty when none is near).
  @doc false
  @spec near(String.t(), [String.t()], (String.t() -> String.t())) :: String.t()
  def near(word, words, show) do
    case words |> Enum.map(&{String.jaro_distance(String.downcase(&1), String.downcase(word)), &1}) |> Enum.filter(&(elem(&1, 0) >= 0.8)) |> Enum.sort_by(&(-elem(&1, 0))) do
      [] -> ""
      near -> "; did you mean " <> (near |> Enum.take(3) |> Enum.map_join(", ", fn {_, w} -> show.(w) end)) <> "?"
    end
  end

  @doc """
  A source in words, as events and the report name it.

      iex> Dolphin.Sensors.describe_source({:named_value, "SMOKE"})
      "NAMED_VALUE SMOKE"
  """
  @spec describe_source(Sensor.source()) :: String.t()
  def describe_source({:named_value, name}), do: "NAMED_VALUE #{name}"
  def describe_source({:message, module, field}), do: "#{module.__mavlink__(:name)}.#{field}"

  @doc """
  A reading's raw number as the sensor's value (`raw × scale + offset`);
  `nil` stays unknown.

      iex> Dolphin.Sensors.value(%Dolphin.Sensors.Sensor{name: :t, source: {:named_value, "T"}, scale: 0.01}, 2150)
      21.5
  """
  @spec value(Sensor.t(), number() | nil) :: float() | nil
  def value(_sensor, nil), do: nil
  def value(%Sensor{scale: scale, offset: offset}, raw), do: raw * scale + offset
end
