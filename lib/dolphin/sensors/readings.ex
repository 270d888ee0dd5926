defmodule Dolphin.Sensors.Readings do
  @moduledoc """
  A vehicle's sensor readings, kept by pure functions: `fold/5` takes one
  received message into them when a watched source says it.

  What is watched is a `watch()` built from the sources declared (`watch/1`
  of `%{source => %{keep: ms, stale_after: [ms]}}`, what
  `Dolphin.Vehicles.watch_sensors/1` keeps for the instance). Each reading
  is a map:

  | key | meaning |
  | --- | --- |
  | `value` | the raw number the message carried (`Dolphin.Sensors.value/2` scales it) |
  | `at` | when it was heard, clock ms |
  | `compid` | the component that said it (191: an onboard computer) |
  | `position` | where the vehicle was then (`Dolphin.Geo.Location`), `nil` while unknown |
  | `history` | `{at, value, position}` of the readings of the last `keep` ms (at most the last 512), newest first (this one included) |
  | `stale` | the `stale_after` limits (ms) this reading has outlived with no newer one (`stale/4`) |

      iex> alias Dolphin.Sensors.Readings
      iex> watch = Readings.watch(%{{:named_value, "SMOKE"} => %{keep: 10_000, stale_after: [5_000]}})
      iex> msg = %Dolphin.MAVLink.Ardupilotmega.NamedValueFloat{name: "SMOKE", value: 0.25}
      iex> r = Readings.fold(%{}, watch, 191, msg, 1_000, nil)
      iex> r[{:named_value, "SMOKE"}].value
      0.25
      iex> r = Readings.fold(r, watch, 191, %{msg | value: 0.5}, 12_000, nil)
      iex> r[{:named_value, "SMOKE"}].history
      [{12000, 0.5, nil}]
  """

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sensors.Sensor

  # Readings kept per source at most (each view carries them to its
  # subscribers): a 2 Hz sensor's whole minute, a 50 Hz one's last ten seconds.
  @max_history 512

  @typedoc "What one source keeps: readings for `keep` ms; the staleness limits declared."
  @type config :: %{keep: pos_integer(), stale_after: [pos_integer()]}

  @typedoc "The sources watched, indexed for the fold: named values by name, message fields by message module."
  @type watch :: %{named: %{String.t() => Sensor.source()}, messages: %{module() => [{atom(), Sensor.source()}]}, keep: %{Sensor.source() => pos_integer()}}

  @type reading :: %{value: number(), at: integer(), compid: byte(), position: Dolphin.Geo.Location.t() | nil, history: [{integer(), number(), Dolphin.Geo.Location.t() | nil}], stale: [pos_integer()]}
  @type t :: %{Sensor.source() => reading()}

  @doc "Nothing watched."
  @spec none() :: watch()
  def none, do: %{named: %{}, messages: %{}, keep: %{}}

  @doc "The watch of the sources in `config` (source => `config()`)."
  @spec watch(%{Sensor.source() => config()}) :: watch()
  def watch(config) do
    Enum.reduce(config, none(), fn
      {{:named_value, name} = source, c}, w ->
        %{w | named: Map.put(w.named, name, source), keep: Map.put(w.keep, source, c.keep)}

      {{:message, module, field} = source, c}, w ->
        %{w | messages: Map.update(w.messages, module, [{field, source}], &[{field, source} | &1]), keep: Map.put(w.keep, source, c.keep)}
    end)
  end

  @doc """
  Merges the declarations of `sensors` into a config: a source declared
  twice keeps the longest `keep` and every `stale_after`.
  """
  @spec declare(%{Sensor.source() => config()}, [Sensor.t()]) :: %{Sensor.source() => config()}
  def declare(config, sensors) do
    Enum.reduce(sensors, config, fn %Sensor{source: source, keep: keep, stale_after: stale}, config ->
      stale = List.wrap(stale)

      Map.update(config, source, %{keep: keep, stale_after: stale}, fn c ->
        %{keep: max(c.keep, keep), stale_after: Enum.sort(Enum.uniq(c.stale_after ++ stale))}
      end)
    end)
  end

  @doc """
  The readings once `message`, heard from component `compid` at clock ms
  `now`, is folded in; `position` is where the vehicle is (or a function
  that says it, called only for a reading). Unchanged (the same term) when
  the message says nothing watched.
  """
  @spec fold(t(), watch(), byte(), struct(), integer(), position | (-> position)) :: t() when position: Dolphin.Geo.Location.t() | nil
  def fold(readings, %{named: named} = w, compid, %M.NamedValueFloat{name: name, value: value}, now, position) when is_map_key(named, name),
    do: named(readings, w, name, value, compid, now, position)

  def fold(readings, %{named: named} = w, compid, %M.NamedValueInt{name: name, value: value}, now, position) when is_map_key(named, name),
    do: named(readings, w, name, value, compid, now, position)

  def fold(readings, %{messages: messages} = w, compid, %module{} = message, now, position) when is_map_key(messages, module) do
    Enum.reduce(Map.fetch!(messages, module), readings, fn {field, source}, readings ->
      put(readings, source, Map.fetch!(message, field), compid, now, position, Map.fetch!(w.keep, source))
    end)
  end

  def fold(readings, _watch, _compid, _message, _now, _position), do: readings

  defp named(readings, w, name, value, compid, now, position) do
    source = Map.fetch!(w.named, name)
    put(readings, source, value, compid, now, position, Map.fetch!(w.keep, source))
  end

  defp put(readings, source, value, compid, now, position, keep) when is_number(value) do
    history =
      case Map.get(readings, source) do
        nil -> []
        %{history: history} -> history
      end

    position = if is_function(position, 0), do: position.(), else: position
    history = [{now, value, position} | history] |> Enum.take(@max_history) |> Enum.take_while(fn {at, _, _} -> now - at <= keep end)
    Map.put(readings, source, %{value: value, at: now, compid: compid, position: position, history: history, stale: []})
  end

  # NaN and infinities arrive as atoms from the codec: nothing was measured.
  defp put(readings, _source, _value, _compid, _now, _position, _keep), do: readings

  @doc """
  The readings once the one of `source` heard at `at` has outlived
  `stale_after` ms with no newer one; `:unchanged` when a newer one came
  (or it was already marked).
  """
  @spec stale(t(), Sensor.source(), integer(), pos_integer()) :: t() | :unchanged
  def stale(readings, source, at, stale_after) do
    case Map.get(readings, source) do
      %{at: ^at, stale: stale} = r -> if stale_after in stale, do: :unchanged, else: Map.put(readings, source, %{r | stale: [stale_after | stale]})
      _ -> :unchanged
    end
  end

  @doc """
  The sources whose reading is newer in `new` than in `old`, with its time:
  what the vehicle's process arms staleness timers for.
  """
  @spec fresh(t(), t()) :: [{Sensor.source(), integer()}]
  def fresh(same, same), do: []

  def fresh(old, new) do
    for {source, %{at: at}} <- new, not match?(%{at: ^at}, Map.get(old, source)), do: {source, at}
  end
end
