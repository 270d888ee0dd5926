defmodule Dolphin.Script do
  @moduledoc """
  Dolphin scripts: `.exs` files that start with `use Dolphin.Script` and are
  run with `mix dolphin.run script.exs` (or `compile/1` and `run/2`). The
  language reference, with a runnable example of every construct, is
  `docs/language.md` in the project.

      use Dolphin.Script

      v = pick(type: :uav, timeout: seconds(30))
      execute %{v => wait_for(battery(v) >= 0.9, then: until(survey, battery(v) < 0.3) >>> return_home)}
      release(v)
      message("Done!")

  A script is plain Elixir plus the words that `use Dolphin.Script` imports
  from `Dolphin.DSL`, `Dolphin.DSL.Values` and `Dolphin.DSL.Mission`:

    * values — `location/3`, `area/2`, `seconds/1`, `minutes/1`, `hours/1`,
      `days/1`, `meters/1`, `km/1`, `percent/1`, `degrees/1`, `distance/2`,
      `near?/3`, `contains?/2` (`Dolphin.DSL.Values`);
    * vehicles — `pick`, `release`, `union`, `difference`, `intersection`,
      `filter`, `set_connection_timeout`, and the readers `battery`,
      `position`, `altitude`, `relative_altitude`, `mode`, `armed?`,
      `connected?`, `mission_progress` (nil until the vehicle has reported
      them; in a condition an unknown value is not met);
    * tasks — `mission "name" do ... end` (the commands of
      `Dolphin.Mission.Command`), `idle`, `action`, `condition`, `>>>`,
      `|||`, `on`, `until`, `during`, `wait_for`, `one_of`, `all_of`,
      `watch`, `named`;
    * statements — `execute`, `forever`, `repeat`, `message`, `post`,
      `consume`, `poll`, `pause`, `halt`, `ask`, `send_message`.

  In the console (`iex -S mix dolphin.console`) `h battery`, `h location`
  show a reader's or a value's documentation; every other word is
  `h Dolphin.DSL.until` (or `h Dolphin.DSL.Mission.mission`,
  `h Dolphin.Mission.Command.survey_area`).

  ## Compiling

  `compile/1` reads a script and compiles it as the body of a function of a
  fresh module — so a syntax error, an unknown word (`pik(type: :uav)`) or an
  unbound variable is reported with file and line (`Dolphin.Script.Error`)
  before anything runs or is sent to a vehicle.

  ## Running

  `run/2` runs a compiled script in its own process, which owns its picks
  (released when it ends) and its signals, and returns a summary or an error
  saying what failed, where (the script line) and why. Options:

    * `:fleet` — the `Dolphin.Fleet` (default: the application's);
    * `:clock` — a `Dolphin.Engine.TimeSource` (default `Dolphin.Clock`);
    * `:for` — stop the script after this much clock time (ms): running tasks
      are stopped (vehicles hold), and the result is `:stopped`;
    * `:ask` — a function from prompt to answer for `ask/1` (default: a line
      of standard input);
    * `:output` — a function given each `message/1` text (default: none; the
      `message` event is emitted either way).

  ## Where the language lives

    * `Dolphin.DSL`, `Dolphin.DSL.Values`, `Dolphin.DSL.Mission` — the words
      (macros and thin functions), which expand to calls of:
    * `Dolphin.Script.Statements` — the statements as plain functions (also
      offered below under this module's name), usable from any process: they
      act for the script that the calling process works for;
    * `Dolphin.Engine` — the tasks and their combinators.

  This module is the facade: it compiles scripts (the compiler is in
  `lib/dolphin/script/`) and runs each in its own runner process, a
  `GenServer` — `:sys.get_state/1` and `:sys.trace/2` on the pid that
  `start/2` returns show a running script.
  """

  alias Dolphin.Engine.Context
  alias Dolphin.Fleet.VehicleSet
  alias Dolphin.Script.{Compiler, Error, Runner, Statements}

  defstruct [:file, :module, :source]

  @type t :: %__MODULE__{file: String.t(), module: module(), source: String.t()}
  @typedoc "How a script ended: its result, how long it ran and when it started (`Dolphin.Clock` ms)."
  @type summary :: %{result: :done | :stopped, duration_ms: non_neg_integer(), started_ms: integer(), file: String.t()}

  @doc false
  defmacro __using__(_opts) do
    mission =
      if Code.ensure_loaded?(Dolphin.DSL.Mission),
        do: quote(do: import(Dolphin.DSL.Mission, only: [mission: 1, mission: 2])),
        else: nil

    quote do
      import Dolphin.DSL
      import Dolphin.DSL.Values
      import Dolphin.DSL.Fence, only: [fence: 1, rally: 1, min_separation: 2]
      import Dolphin.DSL.Sensors, only: [sensor: 2, sensor_age: 2, peak: 3, peak_position: 3, on_sensor: 3]
      unquote(mission)
    end
  end

  # --- compiling ---

  @doc "Reads and compiles a script file (see the module doc)."
  @spec compile(Path.t()) :: {:ok, t()} | {:error, Error.t()}
  def compile(path) do
    case File.read(path) do
      {:ok, source} -> compile_string(source, path)
      {:error, why} -> {:error, %Error{kind: :compile, file: path, message: "cannot read the script: #{:file.format_error(why)}"}}
    end
  end

  @doc "Compiles a script given as a string; `file` is the name errors give."
  @spec compile_string(String.t(), String.t()) :: {:ok, t()} | {:error, Error.t()}
  def compile_string(source, file \\ "nofile") do
    with {:ok, module} <- Compiler.compile(source, file) do
      {:ok, %__MODULE__{file: file, module: module, source: source}}
    end
  end

  @doc "Forgets a compiled script's module."
  @spec purge(t()) :: :ok
  def purge(%__MODULE__{module: module}), do: Compiler.purge(module)

  # --- running ---

  @doc "Runs a compiled script and waits for its end (see the module doc)."
  @spec run(t(), keyword()) :: {:ok, summary()} | {:error, Error.t()}
  def run(%__MODULE__{} = script, opts \\ []) do
    {:ok, pid} = start(script, opts)
    await(pid)
  end

  @doc """
  Starts a script (linked to the caller); see `await/2` and `stop/2`. The
  pid is the script's `Dolphin.Script.Runner`; its end is reported to the
  caller as a message `{Dolphin.Script, pid, result}`, which `await/2` reads.
  """
  @spec start(t(), keyword()) :: {:ok, pid()}
  def start(%__MODULE__{} = script, opts \\ []) do
    # The caller's context (its fleet, clock) is the script's, unless the options say otherwise.
    ctx = Context.new(Keyword.take(opts, [:instance, :fleet, :clock, :tick_ms, :stop_timeout_ms, :ask, :output, :platform_opts]))
    Runner.start_link(script, ctx, Keyword.put(opts, :group_leader, Process.group_leader()), {self(), __MODULE__})
  end

  @doc "Waits for the end of a script started by the caller."
  @spec await(pid(), timeout()) :: {:ok, summary()} | {:error, Error.t()} | {:error, :timeout}
  def await(pid, timeout \\ :infinity) do
    receive do
      {__MODULE__, ^pid, result} -> result
    after
      timeout -> {:error, :timeout}
    end
  end

  @doc """
  Stops a running script: its tasks stop (vehicles hold), then its vehicles
  are released, and its result is `:stopped`. `reason` goes to every task's
  stop and, in words (`Dolphin.Engine.Failure.format_reason/1`), into the
  `task_finished` and `script_finished` events.
  """
  @spec stop(pid(), term()) :: :ok
  def stop(pid, reason \\ :operator), do: Runner.stop(pid, reason)

  # --- statements (see Dolphin.Script.Statements) ---

  @doc "`Dolphin.Script.Statements.pick/1`: picks vehicles for the script."
  @spec pick(keyword()) :: VehicleSet.t()
  defdelegate pick(opts \\ []), to: Statements

  @doc "`Dolphin.Script.Statements.release/1`: releases vehicles the script picked."
  @spec release(VehicleSet.t() | [VehicleSet.t()]) :: :ok
  defdelegate release(sets), to: Statements

  @doc "`Dolphin.Script.Statements.set_connection_timeout/1`."
  @spec set_connection_timeout(pos_integer()) :: :ok
  defdelegate set_connection_timeout(ms), to: Statements

  @doc "`Dolphin.Script.Statements.set_connection_timeout/2`."
  @spec set_connection_timeout(VehicleSet.t(), pos_integer()) :: :ok
  defdelegate set_connection_timeout(set, ms), to: Statements

  @doc "`Dolphin.Script.Statements.execute/1`: runs a task (or a map of tasks) to its end."
  @spec execute(term()) :: :ok | :stopped
  defdelegate execute(tasks), to: Statements

  @doc "`Dolphin.Script.Statements.forever/1`: runs `fun` for ever."
  @spec forever((() -> term())) :: no_return()
  defdelegate forever(fun), to: Statements

  @doc "`Dolphin.Script.Statements.forever/2`: runs `fun` for ever, threading a state."
  @spec forever(term(), (term() -> term())) :: no_return()
  defdelegate forever(state, fun), to: Statements

  @doc "`Dolphin.Script.Statements.repeat/2`: runs `fun` `n` times."
  @spec repeat(non_neg_integer(), (() -> term())) :: :ok
  defdelegate repeat(n, fun), to: Statements

  @doc "`Dolphin.Script.Statements.message/1`: an operator log line."
  @spec message(term()) :: :ok
  defdelegate message(text), to: Statements

  @doc "`Dolphin.Script.Statements.post/2`: posts `value` to signal `key`."
  @spec post(term(), term()) :: :ok
  defdelegate post(key, value), to: Statements

  @doc "`Dolphin.Script.Statements.consume/2`: consumes `value` from signal `key`."
  @spec consume(term(), term()) :: boolean()
  defdelegate consume(key, value), to: Statements

  @doc "`Dolphin.Script.Statements.poll/1`: whether signal `key` has a value."
  @spec poll(term()) :: boolean()
  defdelegate poll(key), to: Statements

  @doc "`Dolphin.Script.Statements.poll/2`: whether signal `key` has a value for which `fun` is truthy."
  @spec poll(term(), (term() -> term())) :: boolean()
  defdelegate poll(key, fun), to: Statements

  @doc "`Dolphin.Script.Statements.pause/1`: pauses for `ms` of clock time."
  @spec pause(non_neg_integer()) :: :ok
  defdelegate pause(ms), to: Statements

  @doc "`Dolphin.Script.Statements.halt/1`: stops the script with a message."
  @dialyzer {:nowarn_function, halt: 0}
  @spec halt(term()) :: no_return()
  defdelegate halt(text \\ "halted"), to: Statements

  @doc "`Dolphin.Script.Statements.ask/1`: asks the operator."
  @spec ask(String.t()) :: String.t() | nil
  defdelegate ask(prompt), to: Statements

  @doc "`Dolphin.Script.Statements.send_message/2`: a raw MAVLink message to every vehicle of `set`."
  @spec send_message(VehicleSet.t(), term()) :: :ok
  defdelegate send_message(set, message), to: Statements
end
