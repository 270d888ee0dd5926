defmodule Dolphin.Console.MissionFile do
  @moduledoc false
  # The missions a script (or a file of missions) defines, found without
  # running the script: for `mix dolphin.plan export` and `list`.
  #
  # The file must be a script (`use Dolphin.Script`) or a file of missions
  # (a `mission` block at its top level). Its top-level definitions are
  # evaluated in order, with the words of `use Dolphin.Script` imported (so a
  # file of bare `mission` blocks needs no `use` line): assignments,
  # directives (`use`, `import`, `alias`, `require`), `defmodule`s and bare
  # `mission` blocks. Other statements are skipped, and so are the
  # assignments that act — that call one of @acting (pick, execute, ...) —
  # and any that raises (it may need a skipped one's result). What remains
  # defines the missions: every variable bound to a mission (or to a list of
  # missions) at the end, and the value of every bare `mission` block. The
  # evaluation runs in its own process, bounded in time.

  alias Dolphin.Console.MissionFileError
  alias Dolphin.Mission

  # The statements of the script language that do something (docs/language.md,
  # "Vehicles" and "Statements"): never run when only missions are wanted.
  @acting [:pick, :release, :execute, :forever, :repeat, :message, :post, :consume, :poll, :pause, :halt, :ask, :send_message, :set_connection_timeout]

  @typedoc "A mission found: `name` is the variable it is bound to (nil for a bare expression)."
  @type found :: %{var: String.t() | nil, mission: Mission.t(), line: pos_integer() | nil}

  @doc false
  # {:ok, missions, notes} — notes say what was skipped and why — or {:error, %MissionFileError{}}.
  @spec read(Path.t(), keyword()) :: {:ok, [found()], [String.t()]} | {:error, MissionFileError.t()}
  def read(path, opts \\ []) do
    timeout = Keyword.get(opts, :timeout, 30_000)

    with {:ok, source} <- read_file(path),
         {:ok, ast} <- parse(source, path),
         :ok <- script_or_missions(statements(ast), path) do
      task = Task.async(fn -> evaluate(statements(ast), path) end)

      case Task.yield(task, timeout) || Task.shutdown(task, :brutal_kill) do
        {:ok, result} -> result
        {:exit, reason} -> {:error, %MissionFileError{reason: :crashed, path: path, detail: inspect(reason)}}
        nil -> {:error, %MissionFileError{reason: :timeout, path: path, detail: "#{div(timeout, 1000)} s"}}
      end
    end
  end

  defp read_file(path) do
    case File.read(path) do
      {:ok, source} -> {:ok, source}
      {:error, :eisdir} -> {:error, %MissionFileError{reason: :unreadable, path: path, detail: "it is a directory, not a script or a file of missions"}}
      {:error, why} -> {:error, %MissionFileError{reason: :unreadable, path: path, detail: List.to_string(:file.format_error(why))}}
    end
  end

  defp parse(source, path) do
    case Code.string_to_quoted(source, file: path) do
      {:ok, ast} ->
        {:ok, ast}

      {:error, {meta, message, token}} ->
        message = if is_tuple(message), do: elem(message, 0) <> elem(message, 1), else: message
        line = if is_list(meta), do: meta[:line], else: meta
        {:error, %MissionFileError{reason: :syntax, path: path, line: line, detail: "#{message}#{token}"}}
    end
  end

  defp script_or_missions(statements, path) do
    script? = Enum.any?(statements, &match?({:use, _, [{:__aliases__, _, [:Dolphin, :Script]} | _]}, &1))
    missions? = Enum.any?(statements, &match?({:mission, _, [_ | _]}, mission_call(&1)))

    if script? or missions?,
      do: :ok,
      else: {:error, %MissionFileError{reason: :not_a_script, path: path}}
  end

  defp mission_call({:=, _, [_, rhs]}), do: mission_call(rhs)
  defp mission_call(other), do: other

  defp statements({:__block__, _, statements}), do: statements
  defp statements(statement), do: [statement]

  defp evaluate(statements, path) do
    prelude =
      quote do
        import Dolphin.DSL
        import Dolphin.DSL.Values
        import Dolphin.DSL.Mission, only: [mission: 1, mission: 2]
      end

    {_, binding, env} = Code.eval_quoted_with_env(prelude, [], Code.env_for_eval(file: path))

    {binding, _env, values, notes} =
      Enum.reduce(statements, {binding, env, [], []}, fn statement, {binding, env, values, notes} ->
        line = line(statement)

        case check(statement) do
          :ok ->
            try do
              Code.eval_quoted_with_env(statement, binding, env)
            rescue
              e -> {binding, env, values, notes ++ ["#{path}:#{line}: not evaluated: #{Exception.message(e) |> first_line()}"]}
            catch
              kind, reason -> {binding, env, values, notes ++ ["#{path}:#{line}: not evaluated: #{kind} #{inspect(reason)}"]}
            else
              {value, binding, env} ->
                values = if match?(%Mission{}, value) and not binds?(statement), do: values ++ [%{var: nil, mission: value, line: line}], else: values
                {binding, env, values, notes}
            end

          {:skip, why} ->
            {binding, env, values, notes ++ ["#{path}:#{line}: skipped (#{why})"]}
        end
      end)

    {:ok, bound(binding) ++ values, notes}
  end

  # Variables bound to missions, or to lists of missions, in name order.
  defp bound(binding) do
    binding
    |> Enum.filter(fn {name, _} -> is_atom(name) end)
    |> Enum.sort()
    |> Enum.flat_map(fn
      {name, %Mission{} = m} ->
        [%{var: Atom.to_string(name), mission: m, line: nil}]

      {name, [%Mission{} | _] = list} ->
        for {m, i} <- Enum.with_index(list), match?(%Mission{}, m), do: %{var: "#{name}[#{i}]", mission: m, line: nil}

      _ ->
        []
    end)
  end

  @directives [:use, :import, :alias, :require]

  # Whether a top-level statement is a definition to evaluate.
  defp check({:defmodule, _, _}), do: :ok
  defp check({d, _, _}) when d in @directives, do: :ok

  defp check({kind, _, _} = statement) when kind in [:=, :mission] do
    case acting(statement) do
      nil -> :ok
      word -> {:skip, "it calls #{word}"}
    end
  end

  defp check(_statement), do: {:skip, "not a definition"}

  defp binds?({:=, _, _}), do: true
  defp binds?(_), do: false

  @doc false
  # The first acting word a statement calls (unqualified), or nil.
  @spec acting(Macro.t()) :: atom() | nil
  def acting(statement) do
    {_, found} =
      Macro.prewalk(statement, nil, fn
        {word, _, args} = node, nil when word in @acting and is_list(args) -> {node, word}
        node, found -> {node, found}
      end)

    found
  end

  defp line({_, meta, _}) when is_list(meta), do: meta[:line]
  defp line(_), do: nil

  defp first_line(text), do: text |> String.split("\n") |> hd()

  @doc false
  # The mission called `name`: by its name or by its variable.
  @spec pick([found()], String.t()) :: {:ok, found()} | {:error, MissionFileError.t()}
  def pick(found, name) do
    case Enum.filter(found, &(&1.mission.name == name or &1.var == name)) do
      [one] ->
        {:ok, one}

      [] ->
        {:error, %MissionFileError{reason: :no_mission, name: name, detail: describe(found)}}

      [first | _] = several ->
        if Enum.all?(several, &(&1.mission == first.mission)),
          do: {:ok, first},
          else: {:error, %MissionFileError{reason: :ambiguous, name: name, detail: Enum.map(several, &label/1)}}
    end
  end

  @doc false
  @spec describe([found()]) :: String.t()
  def describe([]), do: "the file defines no mission"
  def describe(found), do: "the file defines: " <> Enum.map_join(found, ", ", &label/1)

  @doc false
  @spec label(found()) :: String.t()
  def label(%{var: nil, mission: m, line: line}), do: "#{inspect(m.name)} (line #{line})"
  def label(%{var: var, mission: m}), do: "#{inspect(m.name)} (#{var})"
end
