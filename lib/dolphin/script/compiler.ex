defmodule Dolphin.Script.Compiler do
  @moduledoc false
  # Turns a script's source into a module with a `__script__/0` function,
  # saying what is wrong in the script's terms (file:line, did you mean ...)
  # before anything runs; `Dolphin.Script.compile/1` is its public face.

  alias Dolphin.Script.Error

  @spec compile(String.t(), String.t()) :: {:ok, module()} | {:error, Error.t()}
  def compile(source, file) do
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
        compile_reporting_warnings(wrapped, file, module, ast)
        {:ok, module}
      rescue
        e in [CompileError, SyntaxError, TokenMissingError] ->
          {:error, %Error{kind: :compile, file: file, line: e.line, message: compile_message(e.description, ast, module)}}

        # A word of the language given a bad argument, found while the script is
        # compiled: the line is the script's frame in the stack.
        e in ArgumentError ->
          {:error, %Error{kind: :compile, file: file, line: script_line(__STACKTRACE__, file), message: Exception.message(e)}}
      after
        Dolphin.DSL.Sensors.forget(module)
      end
    end
  end

  @spec purge(module()) :: :ok
  def purge(module) do
    :code.purge(module)
    :code.delete(module)
    :ok
  end

  defp script_line(stacktrace, file) do
    Enum.find_value(stacktrace, fn {_m, _f, _a, location} ->
      if to_string(location[:file]) == file, do: location[:line]
    end)
  end

  # The compiler's warnings (an unused variable, ...) name the module the
  # script is compiled into, which means nothing to its author: they are
  # caught and printed in the script's terms, `file:line: warning: ...`.
  # :standard_error is the VM's: two scripts compiled at once (two runs, two
  # instances) take turns with it.
  defp compile_reporting_warnings(wrapped, file, module, ast) do
    :global.trans({{__MODULE__, :standard_error}, self()}, fn -> compile_capturing(wrapped, file, module, ast) end, [node()], :infinity)
  end

  defp compile_capturing(wrapped, file, module, ast) do
    {:ok, capture} = StringIO.open("")
    original = Process.whereis(:standard_error)

    try do
      if original, do: Process.unregister(:standard_error)
      Process.register(capture, :standard_error)
      Code.compile_quoted(wrapped, file)
    after
      # Given back as found, unless someone else took the name meanwhile.
      if Process.whereis(:standard_error) == capture do
        Process.unregister(:standard_error)
        if original && Process.alive?(original), do: Process.register(original, :standard_error)
      end

      {:ok, {_, warnings}} = StringIO.close(capture)
      if warnings != "", do: IO.write(:stderr, script_warnings(warnings, module, ast))
    end
  end

  # Elixir prints each warning as "warning: TEXT" and where it is found on
  # the lines below it: "  FILE:LINE: Module.__script__/0", after "Conflict
  # found at" (a type conflict, whose TEXT has paragraphs of its own) or
  # "Invalid call found at N locations:". Each becomes "FILE:LINE: warning:
  # TEXT", the rest of TEXT indented below it, once per place.
  @doc false
  @spec script_warnings(String.t(), module(), Macro.t()) :: String.t()
  def script_warnings(text, module, ast) do
    text
    |> String.replace(~r/\e\[[0-9;]*m/, "")
    |> String.split(~r/^warning: /m, trim: true)
    |> Enum.map_join(fn warning ->
      {places, lines} = warning |> String.trim_trailing() |> String.split("\n") |> Enum.reverse() |> Enum.split_while(&place?/1)
      message = lines |> Enum.reverse() |> Enum.reject(&(String.trim(&1) == "" or &1 =~ ~r/^(Conflict found at|Invalid call found at \d+ locations:)$/))
      [first | rest] = if message == [], do: [""], else: message
      first = in_script_terms(first, module, ast)
      rest = Enum.map(rest, &("  " <> in_script_terms(&1, module, ast) <> "\n"))

      case Enum.reverse(places) do
        [] -> ["warning: ", first, "\n" | rest]
        places -> Enum.map(places, fn place -> [where(place), ": warning: ", first, "\n" | rest] end)
      end
    end)
  end

  defp place?(line), do: line =~ ~r/^\s+\S+:\d+(:\d+)?(:\s.*)?$/

  defp where(line) do
    [_, where] = Regex.run(~r/^\s+(\S+?:\d+)/, line)
    where
  end

  defp in_script_terms(text, module, ast) do
    internal = inspect(module)

    text
    |> String.replace(~r/^undefined function ([^\s\/]+)\/(\d+) \(expected #{Regex.escape(internal)} to define such a function or for it to be imported, but none are available\)$/, fn whole ->
      [_, name, arity] = Regex.run(~r/^undefined function ([^\s\/]+)\/(\d+)/, whole)
      undefined(name, String.to_integer(arity), ast)
    end)
    |> String.replace(internal <> ".__script__/0", "the script")
    |> String.replace(internal, "the script")
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
      [_, name, arity] -> undefined(name, String.to_integer(arity), ast)
      nil -> String.replace(description, inspect(module), "the script")
    end
  end

  defp undefined(name, arity, ast) do
    hint = if uses_script?(ast), do: did_you_mean(name, arity), else: " (does the script start with `use Dolphin.Script`?)"
    "undefined function #{name}/#{arity}: no word of the language or of Elixir has that name#{hint}"
  end

  # The words `use Dolphin.Script` imports, plus Elixir's own.
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
end
