defmodule Dolphin.Check.Loops do
  @moduledoc false
  # Busy loops of a script, read from its source: a `forever` whose body
  # cannot wait repeats as fast as the machine runs, keeping a core busy for
  # ever (and the dry run cannot tell it from a script waiting on a
  # condition). Only what is known not to wait counts as not waiting: the
  # script's own words that build values and tasks, read vehicles and
  # signals or write messages, Kernel's operators and functions, and the
  # pure modules of the standard library; any other call (`execute`,
  # `pause`, `pick`, `ask`, `receive`, a function value, an unknown module)
  # may wait, so a loop calling one is never reported.

  # Words of Dolphin.DSL, Dolphin.DSL.Values and Kernel that never wait, and
  # the forms of the language (blocks, branches, clauses, data).
  @quiet ~w(
    release union difference intersection filter set_connection_timeout
    battery position altitude relative_altitude mode armed? connected? mission_progress
    idle on during watch reassign named >>> ||| action condition until wait_for one_of all_of
    message post consume poll halt send_message repeat
    location area days hours minutes seconds km meters percent degrees distance near? contains?
    + - * / == != === !== < > <= >= and or not && || ! <> ++ -- in .. = |> ^ | :: & <-
    abs div rem round trunc max min length elem hd tl floor ceil put_elem map_size tuple_size
    is_nil is_number is_integer is_float is_binary is_list is_map is_atom is_boolean is_tuple
    to_string inspect then tap
    __block__ if unless case cond for with fn -> {} %{} % <<>> __aliases__ sigil_s sigil_S sigil_w sigil_W sigil_r
  )a

  @pure_modules [[:Enum], [:Map], [:List], [:String], [:Integer], [:Float], [:Keyword], [:Tuple], [:MapSet], [:Kernel], [:Dolphin, :Geo]]
  # Erlang's pure modules, and Kernel as string interpolation calls it.
  @pure_erlang [:math, :lists, :maps, Kernel]
  # Words that wait even written bare, without parentheses (a variable's form).
  @waits_bare [:pick]

  @doc false
  # The lines of the `forever` loops of `source` whose body never waits.
  @spec busy(String.t(), String.t()) :: [pos_integer()]
  def busy(source, file) do
    case Code.string_to_quoted(source, file: file, columns: false) do
      {:ok, ast} ->
        {_, lines} = Macro.prewalk(ast, [], fn node, acc -> {node, busy_loop(node) ++ acc} end)
        lines |> Enum.uniq() |> Enum.sort()

      {:error, _} ->
        []
    end
  end

  defp busy_loop({:forever, meta, [[do: body]]}), do: if(quiet?(body), do: [meta[:line]], else: [])
  defp busy_loop({:forever, meta, [_state, {:fn, _, _} = fun]}), do: if(quiet?(fun), do: [meta[:line]], else: [])
  defp busy_loop(_node), do: []

  # A mission's block is its commands, values that wait for nothing.
  defp quiet?({:mission, _meta, args}) when is_list(args), do: true
  defp quiet?({name, _meta, context}) when is_atom(name) and is_atom(context), do: name not in @waits_bare
  defp quiet?({name, _meta, args}) when is_atom(name) and is_list(args), do: name in @quiet and Enum.all?(args, &quiet?/1)

  defp quiet?({{:., _, [{:__aliases__, _, mod}, fun]}, _, args}) when is_atom(fun) and is_list(args),
    do: mod in @pure_modules and Enum.all?(args, &quiet?/1)

  defp quiet?({{:., _, [mod, fun]}, _, args}) when is_atom(mod) and is_atom(fun) and is_list(args),
    do: mod in @pure_erlang and Enum.all?(args, &quiet?/1)

  # `value.field`: a map's field, no call.
  defp quiet?({{:., _, [receiver, field]}, meta, []}) when is_atom(field), do: meta[:no_parens] == true and quiet?(receiver)
  defp quiet?({a, b}), do: quiet?(a) and quiet?(b)
  defp quiet?(list) when is_list(list), do: Enum.all?(list, &quiet?/1)
  defp quiet?(literal) when is_atom(literal) or is_number(literal) or is_binary(literal), do: true
  defp quiet?(_other), do: false
end
