defmodule Dolphin.DSL.Sensors do
  @moduledoc """
  Sensors in scripts (docs/language.md, "Sensors"), imported by `use
  Dolphin.Script`:

      sensor :smoke, from: {:named_value, "SMOKE"}, stale_after: seconds(5)
      sensor :water_temp, from: {:message, :SCALED_PRESSURE2, :temperature}, scale: 0.01, unit: :celsius

      wait_for(sensor(v, :smoke) > 0.4)
      until(patrol, peak(v, :smoke, within: seconds(30)) > 0.6)
      message("smoke at \#{inspect(peak_position(v, :smoke, within: seconds(30)))}")

  A declaration is checked when the script is compiled: its options
  (`Dolphin.Sensors.new/2`: the message and field must exist in the
  dialect), and every read names a sensor declared above it — a typo is a
  compile error at its line, with the names that are near. When the script
  runs, the declaration makes every vehicle of the station watch the
  source (`Dolphin.Vehicles.watch_sensors/1`) and says so
  (`sensor_declared` event).

  Readers follow the rules of `battery/1` (`Dolphin.DSL`, "Unknown
  values"): unknown (`nil`) until the vehicle has been heard reporting the
  sensor, and again once the reading is older than the sensor's
  `stale_after:`.
  """

  alias Dolphin.Sensors
  alias Dolphin.Sensors.Sensor

  @doc """
  Declares a sensor (`sensor :name, from: ..., ...`) or reads one
  (`sensor(v, :name)`).

  Declared, it returns the `Dolphin.Sensors.Sensor`. Options: `from:`
  (`{:named_value, "NAME"}` or `{:message, :MESSAGE, :field}`), `scale:`,
  `offset:`, `unit:`, `stale_after:` (ms; a reading older than this with
  no newer one is unknown), `keep:` (ms of readings `peak/3` looks at,
  default 60 s).

  Read, it gives the latest value of the sensor on a one-vehicle set (or a
  system id), `raw × scale + offset`, or `nil`: not heard yet, or stale.

      sensor :smoke, from: {:named_value, "SMOKE"}, stale_after: seconds(5)
      execute(wait_for(sensor(v, :smoke) > 0.4))
  """
  defmacro sensor(name, opts) when is_atom(name) and is_list(opts) do
    sensor = declare!(name, opts, __CALLER__)

    quote do
      Dolphin.Script.Statements.__line__(unquote(__CALLER__.line))
      Dolphin.Script.Statements.sensor(unquote(Macro.escape(sensor)))
    end
  end

  defmacro sensor(v, name) when is_atom(name), do: read(:sensor, v, name, [], __CALLER__)

  defmacro sensor(_v, name) do
    raise CompileError,
      file: __CALLER__.file,
      line: __CALLER__.line,
      description: "sensor/2 reads a sensor named in place (sensor(v, :smoke)) or declares one (sensor :smoke, from: ...), got: #{Macro.to_string(name)}"
  end

  @doc """
  How long ago (clock ms) the vehicle's latest reading of the sensor was
  heard; `nil` before the first.

      wait_for(sensor_age(v, :smoke) > seconds(10), then: return_home)
  """
  defmacro sensor_age(v, name), do: read(:sensor_age, v, name, [], __CALLER__)

  @doc """
  The highest value of the sensor on the vehicle over the last `within:`
  ms (at most the sensor's `keep:`); `nil` when none was heard then.

      until(survey, peak(v, :smoke, within: seconds(30)) > 0.6)
  """
  defmacro peak(v, name, opts), do: read(:peak, v, name, [within(opts, name, __CALLER__)], __CALLER__)

  @doc """
  Where the vehicle was when it read `peak/3`'s value (a
  `Dolphin.Geo.Location`), `nil` when none was heard.

      circle_at = peak_position(v, :smoke, within: seconds(30))
  """
  defmacro peak_position(v, name, opts), do: read(:peak_position, v, name, [within(opts, name, __CALLER__)], __CALLER__)

  @doc """
  Missions flown while a sensor is watched (`Dolphin.Engine.OnSensor`):
  a reading above `above:` at a new place sends the nearest vehicle free to
  fly the task `then:` makes of the `Dolphin.Sensors.Detection`, then its
  mission goes on where it stopped; the others fly on meanwhile. A vehicle
  with nothing left of its mission after its look flies `finally:`.

      on_sensor(%{a => west, b => east}, :smoke, above: 0.4, apart: 150, then: fn d -> look_at.(d.position) end, finally: home)
  """
  defmacro on_sensor(missions, name, opts) do
    sensor = fetch!(name, __CALLER__)
    at_line = Dolphin.DSL.Expand.meta(__CALLER__)
    quote(do: Dolphin.Engine.on_sensor(unquote(missions), unquote(Macro.escape(sensor)), [meta: unquote(at_line)] ++ unquote(opts)))
  end

  # The readers above as a condition calls them: their snapshot versions,
  # given the sensor declared (Dolphin.DSL.Expand rewrites them).
  @doc false
  @spec readers() :: [{atom(), non_neg_integer()}]
  def readers, do: [sensor: 2, sensor_age: 2, peak: 3, peak_position: 3]

  @doc false
  # A reader's call in a condition, as a call of Dolphin.Engine.Snapshot
  # reading `snapshot`; nil for a declaration.
  @spec rewrite(atom(), [Macro.t()], Macro.t(), Macro.Env.t()) :: Macro.t() | nil
  def rewrite(:sensor, [_name, opts], _snapshot, _caller) when is_list(opts), do: nil
  def rewrite(:sensor, [v, name], snapshot, caller), do: snapshot_call(:sensor, snapshot, v, name, [], caller)
  def rewrite(:sensor_age, [v, name], snapshot, caller), do: snapshot_call(:sensor_age, snapshot, v, name, [], caller)
  def rewrite(fun, [v, name, opts], snapshot, caller) when fun in [:peak, :peak_position], do: snapshot_call(fun, snapshot, v, name, [within(opts, name, caller)], caller)

  defp read(fun, v, name, extra, caller), do: snapshot_call(fun, nil, v, name, extra, caller)

  defp snapshot_call(fun, snapshot, v, name, extra, caller) do
    sensor = fetch!(name, caller)
    check_within(fun, sensor, extra, caller)
    quote(do: Dolphin.Engine.Snapshot.unquote(fun)(unquote(snapshot), unquote(v), unquote(Macro.escape(sensor)), unquote_splicing(extra)))
  end

  defp within(opts, name, caller) do
    case opts do
      [within: ms] -> ms
      _ -> compile_error(caller, "#{inspect(name)}: peak and peak_position take within: ms (within: seconds(30)), got: #{Macro.to_string(opts)}")
    end
  end

  # A window written as a fixed value is checked against what the sensor keeps.
  defp check_within(fun, %Sensor{keep: keep, name: name}, [ms], caller) when fun in [:peak, :peak_position] do
    case constant(ms, caller) do
      {:ok, within} when is_integer(within) and within > 0 and within <= keep ->
        :ok

      {:ok, within} when is_integer(within) and within > 0 ->
        compile_error(caller, "#{fun}(_, #{inspect(name)}, within: #{within}): sensor #{inspect(name)} keeps #{keep} ms of readings; declare it with keep: #{within} or more")

      {:ok, other} ->
        compile_error(caller, "#{fun}(_, #{inspect(name)}, ...): within: takes a duration in ms (seconds(30)), got: #{inspect(other)}")

      :error ->
        :ok
    end
  end

  defp check_within(_fun, _sensor, _extra, _caller), do: :ok

  # --- declarations, kept while the script compiles ---

  defp declare!(name, opts_ast, caller) do
    opts =
      case constant(opts_ast, caller) do
        {:ok, opts} -> opts
        :error -> compile_error(caller, "sensor #{inspect(name)}: its options are fixed values (from: {:named_value, \"SMOKE\"}, stale_after: seconds(5)), got: #{Macro.to_string(opts_ast)}")
      end

    case Sensors.new(name, opts) do
      {:ok, sensor} ->
        declared = declared(caller)

        case Map.fetch(declared, name) do
          {:ok, %Sensor{} = earlier} when earlier != sensor -> compile_error(caller, "sensor #{inspect(name)} is declared twice, differently")
          _ -> Process.put(key(caller), Map.put(declared, name, sensor))
        end

        sensor

      {:error, why} ->
        compile_error(caller, why)
    end
  end

  defp fetch!(name, caller) when is_atom(name) do
    declared = declared(caller)

    case Map.fetch(declared, name) do
      {:ok, sensor} ->
        sensor

      :error when declared == %{} ->
        compile_error(caller, "unknown sensor #{inspect(name)}: no sensor is declared above this line (sensor #{inspect(name)}, from: {:named_value, \"NAME\"})")

      :error ->
        names = declared |> Map.keys() |> Enum.map(&Atom.to_string/1)
        near = Sensors.near(Atom.to_string(name), names, &":#{&1}")
        compile_error(caller, "unknown sensor #{inspect(name)}#{near}; declared: #{names |> Enum.sort() |> Enum.map_join(", ", &":#{&1}")}")
    end
  end

  defp fetch!(name, caller), do: compile_error(caller, "a sensor is named by an atom written in place (:smoke), got: #{Macro.to_string(name)}")

  @doc false
  # The sensors declared so far in the module `caller` compiles (a script;
  # nil in the console, where they last the session).
  @spec declared(Macro.Env.t() | module() | nil) :: %{atom() => Sensor.t()}
  def declared(%Macro.Env{} = caller), do: Process.get(key(caller), %{})
  def declared(module), do: Process.get({__MODULE__, module}, %{})

  @doc false
  # What a script's compilation kept, once it is compiled.
  @spec forget(module()) :: :ok
  def forget(module) do
    Process.delete({__MODULE__, module})
    :ok
  end

  defp key(%Macro.Env{module: module}), do: {__MODULE__, module}

  @doc false
  # `pick`'s options with `sensors: [:name, ...]` written in place as the sensors declared.
  @spec pick_opts(Macro.t(), Macro.Env.t()) :: Macro.t()
  def pick_opts(opts, caller) when is_list(opts) do
    case Keyword.fetch(opts, :sensors) do
      {:ok, names} when is_list(names) -> Keyword.put(opts, :sensors, Macro.escape(Enum.map(names, &fetch!(&1, caller))))
      {:ok, other} -> compile_error(caller, "pick sensors: takes a list of declared sensors written in place ([:smoke]), got: #{Macro.to_string(other)}")
      :error -> opts
    end
  end

  def pick_opts(opts, _caller), do: opts

  # The value of an expression made of literals and the language's words
  # (seconds(5)); :error when it needs the script's variables.
  defp constant(ast, caller) do
    if Macro.prewalk(ast, true, fn
         {name, _, context} = node, ok when is_atom(name) and is_atom(context) -> {node, ok and false}
         node, ok -> {node, ok}
       end)
       |> elem(1) do
      {value, _} = Code.eval_quoted(ast, [], caller)
      {:ok, value}
    else
      :error
    end
  rescue
    _ -> :error
  end

  defp compile_error(caller, description), do: raise(CompileError, file: caller.file, line: caller.line, description: description)
end
