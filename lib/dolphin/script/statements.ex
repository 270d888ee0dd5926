defmodule Dolphin.Script.Statements do
  @moduledoc """
  The statements of the script language as plain functions: what the words
  of `Dolphin.DSL` (`pick`, `execute`, `message`, `post`, `halt`, ...)
  expand or delegate to. They work without the macros, from any process: they
  act for the script that the calling process works for (its
  `Dolphin.Engine.Context`: fleet, clock, signals, picks).

      set = Dolphin.Script.Statements.pick(type: :uav, timeout: 30_000)
      :ok = Dolphin.Script.Statements.execute(Dolphin.Engine.on(survey, set))
      Dolphin.Script.Statements.message("Done!")

  `Dolphin.Script` offers the same functions under its own name.
  """

  alias Dolphin.Engine
  alias Dolphin.Engine.{Context, Signals}
  alias Dolphin.Fleet
  alias Dolphin.Fleet.VehicleSet
  alias Dolphin.Script.Halt

  @line_key :"$dolphin_line"

  @doc false
  # The script line of the statement about to run (set by the DSL's
  # `execute`, `pick` and `halt`), for errors whose stack has lost it.
  @spec __line__(pos_integer()) :: term()
  def __line__(line), do: Process.put(@line_key, line)

  @doc false
  # The last line given to `__line__/1` in the calling process.
  @spec __line__() :: pos_integer() | nil
  def __line__, do: Process.get(@line_key)

  @doc "Picks vehicles for the script (see `Dolphin.Fleet`); raises `Dolphin.Fleet.PickError` on timeout."
  @spec pick(keyword()) :: VehicleSet.t()
  def pick(opts \\ []) do
    ctx = Context.current()

    case Fleet.pick(ctx.fleet, ctx.owner, opts) do
      {:ok, set} -> set
      {:error, error} -> raise error
    end
  end

  @doc "Releases vehicles the script picked."
  @spec release(VehicleSet.t() | [VehicleSet.t()]) :: :ok
  def release(sets) do
    ctx = Context.current()
    Fleet.release(ctx.fleet, ctx.owner, sets)
  end

  @doc """
  Makes `fence` (a `Dolphin.Fence`) the fence of the missions the script
  flies from its next `execute` on, keeping the rally points already set
  when it has none; returns it.
  """
  @spec fence(Dolphin.Fence.t()) :: Dolphin.Fence.t()
  def fence(%Dolphin.Fence{} = fence) do
    ctx = Context.current()
    fence = if fence.rally == [], do: %{fence | rally: script_fence(ctx).rally}, else: fence
    put_platform_opt(ctx, :fence, fence)
    fence
  end

  @doc """
  The least separation between two of the script's vehicles, which the
  pre-flight check and, in flight, the separation monitor hold them to:
  `horizontal` metres across or `vertical` metres in height (default 20
  and 10).
  """
  @spec min_separation(number(), number()) :: :ok
  def min_separation(horizontal, vertical) when is_number(horizontal) and horizontal > 0 and is_number(vertical) and vertical > 0 do
    ctx = Context.current()
    put_platform_opt(ctx, :min_separation, %{horizontal: horizontal * 1.0, vertical: vertical * 1.0})
    :ok
  end

  def min_separation(horizontal, vertical),
    do: raise(ArgumentError, "min_separation takes metres across and in height, each more than 0, got: #{inspect(horizontal)}, #{inspect(vertical)}")

  @doc """
  A script's sensor declaration, once it runs: every vehicle of the station
  watches its source from now on (`Dolphin.Vehicles.watch_sensors/1`), and
  the event `sensor_declared` says what it reads (the flight report plots
  it). Returns the sensor.
  """
  @spec sensor(Dolphin.Sensors.Sensor.t()) :: Dolphin.Sensors.Sensor.t()
  def sensor(%Dolphin.Sensors.Sensor{} = sensor) do
    ctx = Context.current()
    :ok = Dolphin.Vehicles.watch_sensors([sensor])

    Dolphin.Events.emit(
      :sensor_declared,
      %{sensor: sensor.name, source: Dolphin.Sensors.describe_source(sensor.source), unit: sensor.unit, scale: sensor.scale, offset: sensor.offset, stale_after: sensor.stale_after},
      ctx.clock.now_ms()
    )

    sensor
  end

  @doc "Sets the rally points of the script's fence (`Dolphin.Fence`'s `rally`)."
  @spec rally([Dolphin.Geo.Location.t()]) :: :ok
  def rally(points) do
    ctx = Context.current()

    case Dolphin.Fence.put_rally(script_fence(ctx), points) do
      {:ok, fence} -> put_platform_opt(ctx, :fence, fence)
      {:error, why} -> raise ArgumentError, why
    end

    :ok
  end

  defp script_fence(ctx), do: Keyword.get(ctx.platform_opts, :fence) || %Dolphin.Fence{}

  # What every mission the script flies from now on is given (Dolphin.Mission.Platform's options).
  defp put_platform_opt(ctx, key, value), do: Context.put(%{ctx | platform_opts: Keyword.put(ctx.platform_opts, key, value)})

  @doc "Sets the connection timeout (ms) of the vehicles the script picked and will pick."
  @spec set_connection_timeout(pos_integer()) :: :ok
  def set_connection_timeout(ms) do
    ctx = Context.current()
    Fleet.set_connection_timeout(ctx.fleet, ctx.owner, ms)
  end

  @doc "Sets the connection timeout (ms) of the vehicles of `set`."
  @spec set_connection_timeout(VehicleSet.t(), pos_integer()) :: :ok
  def set_connection_timeout(set, ms) when is_integer(ms) and ms > 0 do
    source = Context.source(Context.current())
    Enum.each(VehicleSet.ids(VehicleSet.new(set)), &Dolphin.Fleet.Source.set_timeout(source, &1, ms))
  end

  def set_connection_timeout(_set, ms), do: raise(ArgumentError, "a connection timeout is a positive number of milliseconds, got: #{inspect(ms)}")

  @doc """
  Runs a task and returns `:ok` when it is done; a failure raises
  (`Dolphin.Engine.TaskError`, `Dolphin.Fleet.AllocationError`) and stops the
  script unless a `watch` handles it. A map `%{set => task, _: task}` runs each
  task on its own set (`_`: any picked vehicle), all at the same time.
  """
  @spec execute(term()) :: :ok | :stopped
  def execute(tasks) when is_map(tasks) and not is_struct(tasks), do: execute(Map.to_list(tasks))

  def execute([{_, _} | _] = pairs) do
    {wild, bound} = Enum.split_with(pairs, fn {k, _} -> k == :_ end)

    tasks =
      Enum.map(Enum.sort_by(bound, fn {set, _} -> VehicleSet.ids(VehicleSet.new(set)) end), fn {set, t} -> Engine.on(t, set) end) ++
        Enum.map(wild, &elem(&1, 1))

    case tasks do
      [one] -> execute(one)
      many -> execute(Engine.concurrent(many))
    end
  end

  def execute(task) do
    ctx = Context.current()
    Engine.execute!(task, fleet: ctx.fleet, clock: ctx.clock, owner: ctx.owner)
  end

  @doc "Runs `fun` for ever."
  @spec forever((() -> term())) :: no_return()
  def forever(fun) when is_function(fun, 0) do
    fun.()
    forever(fun)
  end

  @doc "Runs `fun` for ever, each round given what the previous one returned (first: `state`)."
  @spec forever(term(), (term() -> term())) :: no_return()
  def forever(state, fun) when is_function(fun, 1), do: forever(fun.(state), fun)

  @doc "Runs `fun` `n` times."
  @spec repeat(non_neg_integer(), (() -> term())) :: :ok
  def repeat(n, fun) when is_integer(n) and n >= 0 and is_function(fun, 0), do: Enum.each(1..n//1, fn _ -> fun.() end)
  def repeat(n, _fun), do: raise(ArgumentError, "repeat takes a number of times, got: #{inspect(n)}")

  @doc "An operator log line (a `message` event; printed by `mix dolphin.run`)."
  @spec message(term()) :: :ok
  def message(text) do
    # Lists print as lists: `message(ids)` of vehicle 99 is "[99]", not 'c'.
    text = if is_binary(text), do: text, else: inspect(text, charlists: :as_lists)
    ctx = Context.current()
    Dolphin.Events.emit(:message, %{text: text}, ctx.clock.now_ms())
    if ctx.output, do: ctx.output.(text)
    :ok
  end

  @doc "Posts `value` to the script's signal `key`."
  @spec post(term(), term()) :: :ok
  def post(key, value) do
    ctx = Context.current()
    Dolphin.Events.emit(:signal_posted, %{key: key, value: value}, ctx.clock.now_ms())
    Signals.post(ctx.signals, key, value)
  end

  @doc "Consumes `value` from signal `key`: true if it was there."
  @spec consume(term(), term()) :: boolean()
  def consume(key, value) do
    ctx = Context.current()
    consumed = Signals.consume(ctx.signals, key, value)
    if consumed, do: Dolphin.Events.emit(:signal_consumed, %{key: key, value: value}, ctx.clock.now_ms())
    consumed
  end

  @doc "Whether signal `key` has a value."
  @spec poll(term()) :: boolean()
  def poll(key), do: Signals.poll(Context.current().signals, key)

  @doc "Whether signal `key` has a value for which `fun` is truthy."
  @spec poll(term(), (term() -> term())) :: boolean()
  def poll(key, fun), do: Signals.poll(Context.current().signals, key, fun)

  @doc "Pauses for `ms` of clock time."
  @spec pause(non_neg_integer()) :: :ok
  def pause(ms) when is_number(ms) and ms >= 0, do: Context.current().clock.sleep(round(ms))
  def pause(ms), do: raise(ArgumentError, "pause takes milliseconds, got: #{inspect(ms)}")

  @doc "Stops the script (all its tasks) with a message; the script's result is `:halted`."
  @dialyzer {:nowarn_function, halt: 0}
  @spec halt(term()) :: no_return()
  def halt(text \\ "halted") do
    text = if is_binary(text), do: text, else: inspect(text, charlists: :as_lists)
    ctx = Context.current()
    # From a task's process the script's runner is told directly: raising
    # there only fails that task.
    if ctx.script && ctx.owner != self(), do: send(ctx.script, {:"$dolphin_halt", text})
    raise Halt, message: text
  end

  @doc "Asks the operator: prints `prompt`, returns the line typed (without its newline; nil at end of input)."
  @spec ask(String.t()) :: String.t() | nil
  def ask(prompt) do
    case Context.current().ask do
      nil ->
        case IO.gets(prompt <> " ") do
          line when is_binary(line) -> String.trim_trailing(line, "\n")
          _ -> nil
        end

      fun ->
        fun.(prompt)
    end
  end

  @doc """
  A one-vehicle set's parameter `name`, typed (an integer for the integer
  types); raises `Dolphin.ParamError` (no such parameter, with the names
  near; the vehicle did not answer).
  """
  @spec param(VehicleSet.t() | term(), String.t()) :: number()
  def param(v, name) when is_binary(name), do: param!(v, name, nil)
  def param(_v, name), do: raise(ArgumentError, "param takes the parameter's name as a string (\"WPNAV_SPEED\"), got: #{inspect(name)}")

  @doc """
  Sets a one-vehicle set's parameter `name` to `value` and reads it back;
  returns the value kept. Raises `Dolphin.ParamError` when the vehicle keeps
  another (a whole number for an integer type), has no such parameter or does not answer.
  """
  @spec set_param(VehicleSet.t() | term(), String.t(), number()) :: number()
  def set_param(v, name, value) when is_binary(name) and is_number(value), do: param!(v, name, value)

  def set_param(_v, name, value),
    do: raise(ArgumentError, "set_param takes the parameter's name as a string and a number, got: #{inspect(name)}, #{inspect(value)}")

  defp param!(v, name, value) do
    id = VehicleSet.one!(v, if(value == nil, do: :param, else: :set_param))

    case Dolphin.Fleet.Source.param(Context.source(Context.current()), id, name, value) do
      {:ok, kept} -> kept
      {:error, e} -> raise e
    end
  end

  @doc "Sends a raw message (a MAVLink message struct) to every vehicle of `set`."
  @spec send_message(VehicleSet.t(), term()) :: :ok
  def send_message(set, message) do
    source = Context.source(Context.current())
    Enum.each(VehicleSet.ids(VehicleSet.new(set)), &Dolphin.Fleet.Source.send_message(source, &1, message))
  end
end
