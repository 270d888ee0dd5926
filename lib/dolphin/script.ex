defmodule Dolphin.Script do
  @moduledoc """
  Dolphin scripts: `.exs` files that start with `use Dolphin.Script` and are
  run with `mix dolphin.run script.exs` (or `compile/2` and `run/2`). The
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

  `compile/2` reads a script and compiles it as the body of a function of a
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

  The functions below are the statements of the language, usable from any
  process (they act for the script that the calling process works for).
  """

  alias Dolphin.Engine
  alias Dolphin.Engine.{Context, Signals}
  alias Dolphin.Fleet
  alias Dolphin.Fleet.VehicleSet

  defstruct [:file, :module, :source]

  @type t :: %__MODULE__{file: String.t(), module: module(), source: String.t()}
  @type summary :: %{result: :done | :stopped, duration_ms: non_neg_integer(), file: String.t()}

  defmodule Error do
    @moduledoc """
    Why a script could not be compiled or did not complete: `kind` is
    `:syntax`, `:compile`, `:failed` (a task or the code failed), `:halted`
    (the script called `halt/1`); `file` and `line` say where in the script.
    """
    defexception [:kind, :file, :line, :column, :message, :reason]

    @type t :: %__MODULE__{
            kind: :syntax | :compile | :failed | :halted,
            file: String.t() | nil,
            line: pos_integer() | nil,
            column: pos_integer() | nil,
            message: String.t(),
            reason: term()
          }

    @doc "`file:line: message` (`file:line:column:` for a syntax error)"
    def format(%__MODULE__{file: file, line: line, column: column, message: message}) do
      where = Enum.reject([file && Path.relative_to_cwd(file), line, line && column], &is_nil/1) |> Enum.join(":")
      if where == "", do: message, else: "#{where}: #{message}"
    end
  end

  defmodule Halt do
    @moduledoc "Raised by `Dolphin.Script.halt/1` to stop the script."
    defexception message: "halted"
  end

  @doc false
  defmacro __using__(_opts) do
    mission =
      if Code.ensure_loaded?(Dolphin.DSL.Mission),
        do: quote(do: import(Dolphin.DSL.Mission, only: [mission: 1, mission: 2])),
        else: nil

    quote do
      import Dolphin.DSL
      import Dolphin.DSL.Values
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
    with {:ok, ast} <- parse(source, file) do
      module = Module.concat(Dolphin.Script.Compiled, "S#{System.unique_integer([:positive])}")

      wrapped =
        quote do
          defmodule unquote(module) do
            @moduledoc false
            # Not a tail call: the script's own frame stays in stack traces.
            def __script__ do
              _ = unquote(ast)
              :ok
            end
          end
        end

      try do
        compile_reporting_warnings(wrapped, file, module)
        {:ok, %__MODULE__{file: file, module: module, source: source}}
      rescue
        e in [CompileError, SyntaxError, TokenMissingError] ->
          {:error, %Error{kind: :compile, file: file, line: e.line, message: compile_message(e.description, ast, module)}}

        # A word of the language given a bad argument, found while the script is
        # compiled: the line is the script's frame in the stack.
        e in ArgumentError ->
          {:error, %Error{kind: :compile, file: file, line: script_line(__STACKTRACE__, file), message: Exception.message(e)}}
      end
    end
  end

  defp script_line(stacktrace, file) do
    Enum.find_value(stacktrace, fn {_m, _f, _a, location} ->
      if to_string(location[:file]) == file, do: location[:line]
    end)
  end

  # The compiler's warnings (an unused variable, ...) name the module the
  # script is compiled into, which means nothing to its author: they are
  # caught and printed in the script's terms, `file:line: warning: ...`.
  defp compile_reporting_warnings(wrapped, file, module) do
    {:ok, capture} = StringIO.open("")
    original = Process.whereis(:standard_error)

    try do
      Process.unregister(:standard_error)
      Process.register(capture, :standard_error)
      Code.compile_quoted(wrapped, file)
    after
      Process.unregister(:standard_error)
      Process.register(original, :standard_error)
      {:ok, {_, warnings}} = StringIO.close(capture)
      if warnings != "", do: IO.write(:stderr, script_warnings(warnings, module))
    end
  end

  # "warning: TEXT\n  FILE:LINE: Module.__script__/0\n" -> "FILE:LINE: warning: TEXT\n"
  defp script_warnings(text, module) do
    internal = inspect(module)

    text
    |> String.split(~r/\n\n+/, trim: true)
    |> Enum.map_join(fn warning ->
      case Regex.run(~r/\A(?:warning: )?(.*?)\n\s+(\S+?:\d+)(?::\s*\S+)?\s*\z/s, warning) do
        [_, message, where] -> "#{where}: warning: #{String.trim(message)}\n"
        nil -> String.replace(warning, internal <> ".__script__/0", "the script") <> "\n"
      end
    end)
  end

  defp parse(source, file) do
    case Code.string_to_quoted(source, file: file, columns: true) do
      {:ok, ast} ->
        {:ok, ast}

      {:error, {meta, message, token}} ->
        {line, column} = if is_list(meta), do: {meta[:line], meta[:column]}, else: {meta, nil}
        {:error, %Error{kind: :syntax, file: file, line: line, column: column, message: syntax_error(syntax_message(message, token))}}
    end
  end

  # Elixir's parser gives a message in two parts around the token ("unexpected
  # reserved word: " "end" ". The \"(\" at line 6 is missing terminator
  # \")\""), or one part followed by it.
  defp syntax_message({prefix, suffix}, token) do
    prefix = String.trim_trailing(prefix, ": ") |> String.trim_trailing(":")
    suffix = suffix |> String.trim_leading(".") |> String.trim() |> lower_first()
    "#{prefix} #{inspect(to_string(token))}" <> if(suffix == "", do: "", else: ": " <> suffix)
  end

  defp syntax_message(message, token) when is_binary(message) do
    case to_string(token) do
      "" -> message
      token -> String.trim_trailing(message) <> " " <> token
    end
  end

  defp syntax_error("syntax error" <> _ = message), do: message
  defp syntax_error(message), do: "syntax error: " <> message

  defp lower_first(<<first::utf8, rest::binary>>), do: String.downcase(<<first::utf8>>) <> rest
  defp lower_first(""), do: ""

  # "undefined function wait_fro/1 (expected Dolphin.Script.Compiled.S162 to
  # define such a function ...)": said in the script's terms, with the
  # nearest words of the language.
  defp compile_message(description, ast, module) do
    case Regex.run(~r/\Aundefined function ([^\s\/]+)\/(\d+)/, description) do
      [_, name, arity] ->
        hint = if uses_script?(ast), do: did_you_mean(name, String.to_integer(arity)), else: " (does the script start with `use Dolphin.Script`?)"
        "undefined function #{name}/#{arity}: no word of the language or of Elixir has that name#{hint}"

      nil ->
        String.replace(description, inspect(module), "the script")
    end
  end

  @vocabulary_modules [Dolphin.DSL, Dolphin.DSL.Values, Dolphin.DSL.Mission, Kernel]

  defp did_you_mean(name, arity) do
    words =
      for module <- @vocabulary_modules,
          Code.ensure_loaded?(module),
          {word, n} <- module.__info__(:functions) ++ module.__info__(:macros),
          word = Atom.to_string(word),
          not String.starts_with?(word, "_"),
          uniq: true,
          do: {word, n}

    case words |> Enum.map(fn {w, n} -> {String.jaro_distance(w, name), w, n} end) |> Enum.filter(&(elem(&1, 0) >= 0.8)) |> Enum.sort_by(&{-elem(&1, 0), abs(elem(&1, 2) - arity)}) do
      [] -> ""
      near -> "; did you mean " <> (near |> Enum.map(fn {_, w, n} -> "#{w}/#{n}" end) |> Enum.uniq() |> Enum.take(3) |> Enum.join(", ")) <> "?"
    end
  end

  defp uses_script?(ast) do
    {_, found} = Macro.prewalk(ast, false, fn
      {:use, _, [{:__aliases__, _, [:Dolphin, :Script]} | _]} = node, _ -> {node, true}
      node, acc -> {node, acc}
    end)

    found
  end

  @doc "Forgets a compiled script's module."
  @spec purge(t()) :: :ok
  def purge(%__MODULE__{module: module}) do
    :code.purge(module)
    :code.delete(module)
    :ok
  end

  # --- running ---

  @doc "Runs a compiled script and waits for its end (see the module doc)."
  @spec run(t(), keyword()) :: {:ok, summary()} | {:error, Error.t()}
  def run(%__MODULE__{} = script, opts \\ []) do
    {:ok, pid} = start(script, opts)
    await(pid)
  end

  @doc "Starts a script (linked to the caller); see `await/2` and `stop/2`."
  @spec start(t(), keyword()) :: {:ok, pid()}
  def start(%__MODULE__{} = script, opts \\ []) do
    # The caller's context (its fleet, clock) is the script's, unless the options say otherwise.
    ctx = Context.new(Keyword.take(opts, [:fleet, :clock, :tick_ms, :stop_timeout_ms, :ask, :output]))
    Dolphin.Script.Runner.start_link(script, ctx, opts, self())
  end

  @doc "Waits for the end of a script started by the caller."
  @spec await(pid(), timeout()) :: {:ok, summary()} | {:error, Error.t()} | {:error, :timeout}
  def await(pid, timeout \\ :infinity) do
    receive do
      {Dolphin.Script, ^pid, result} -> result
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
  def stop(pid, reason \\ :operator), do: send(pid, {:"$dolphin_script_stop", reason}) && :ok

  # --- statements ---

  @doc false
  # The script line of the statement about to run (set by the DSL's
  # `execute`, `pick` and `halt`), for errors whose stack has lost it.
  def __line__(line), do: Process.put(:"$dolphin_line", line)

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
    Dolphin.Telemetry.emit(:message, %{text: text}, ctx.clock.now_ms())
    if ctx.output, do: ctx.output.(text)
    :ok
  end

  @doc "Posts `value` to the script's signal `key`."
  @spec post(term(), term()) :: :ok
  def post(key, value) do
    ctx = Context.current()
    Dolphin.Telemetry.emit(:signal_posted, %{key: key, value: value}, ctx.clock.now_ms())
    Signals.post(ctx.signals, key, value)
  end

  @doc "Consumes `value` from signal `key`: true if it was there."
  @spec consume(term(), term()) :: boolean()
  def consume(key, value) do
    ctx = Context.current()
    consumed = Signals.consume(ctx.signals, key, value)
    if consumed, do: Dolphin.Telemetry.emit(:signal_consumed, %{key: key, value: value}, ctx.clock.now_ms())
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

  @doc "Sends a raw message (a MAVLink message struct) to every vehicle of `set`."
  @spec send_message(VehicleSet.t(), term()) :: :ok
  def send_message(set, message) do
    source = Context.source(Context.current())
    Enum.each(VehicleSet.ids(VehicleSet.new(set)), &Dolphin.Fleet.Source.send_message(source, &1, message))
  end
end
