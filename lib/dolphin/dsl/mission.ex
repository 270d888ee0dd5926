defmodule Dolphin.DSL.Mission do
  @moduledoc """
  The `mission` block of scripts: sugar over `Dolphin.Mission.new/2` and the
  command functions of `Dolphin.Mission.Command`.

      import Dolphin.DSL.Mission
      import Dolphin.DSL.Values

      home_pos = location(40.444233, -7.375234, 820)

      survey =
        mission "Survey Area 1" do
          home home_pos
          take_off location(40.444233, -7.375234, 1200)
          survey_area 3000, 10000, 500, :north_east
          capture_several_photos 10, 2
        end

  The block is ordinary Elixir run in place (variables of the enclosing scope
  are seen, `if`, `case`, `for`, `Enum`, function calls all work). Inside it,
  the words of Table 2 (`move`, `delay`, `survey_area`, ... — every public
  function of `Dolphin.Mission.Command`, `name` and `home` included) are the
  mission's commands, whatever else is imported. The mission is made of the
  values of the block's expressions, in order:

    * a command, or a list of commands (from `for` or `Enum.map`), or another
      mission (its commands), or `nil` (an `if` without `else`) — skipped;
    * the bodies of `if`, `unless`, `case`, `cond` and `for` count every
      expression, like the block itself: `for p <- points do go_pos p; capture_photo() end`
      gives two commands per point;
    * a match (`x = ...`) is a statement and adds nothing;
    * anything else is a mistake, raised as `ArgumentError` when the block
      runs (`Enum.each` returns `:ok`: use `for`).

  Mistakes the macro sees are compile errors: a command with an arity it does
  not have, a command whose value would be thrown away (in the middle of a
  `fn` body), a duration value (`seconds(30)`, milliseconds) given where the
  report's commands take seconds.

  `mission do ... end` without a name takes it from a `name "..."` command
  (default `"mission"`); a `name` command inside a named block wins.

      iex> import Dolphin.DSL.Mission
      iex> points = [Dolphin.Geo.location(41.1, -8.6, 100), Dolphin.Geo.location(41.2, -8.6, 100)]
      iex> m = mission "Tour" do
      ...>   home 41.0, -8.6, 50
      ...>   for p <- points, do: go_pos p
      ...>   if length(points) > 1, do: return_home_and_land()
      ...> end
      iex> Enum.map(m.commands, & &1.kind)
      [:go_pos, :go_pos, :return_home_and_land]
  """

  alias Dolphin.Mission.Command

  @time_args %{
    delay: [0],
    loiter_time: [1, 3],
    move_and_loiter_time: [3],
    move_and_loiter_time_from_home: [3],
    capture_several_photos: [1],
    capture_until_stop: [0]
  }
  @duration_values [:seconds, :minutes, :hours, :days]

  @doc """
  A mission named `name` (a `%Dolphin.Mission{}`, plain data: nothing flies
  until `execute`) from the commands of the block, in order (see the module
  doc for what the block may hold, and `Dolphin.Mission.Command` for the
  commands).

      survey =
        mission "Survey Area 1" do
          home location(40.444233, -7.375234, 820)
          take_off location(40.444233, -7.375234, 1200)
          survey_area 3000, 10000, 500, :north_east
          capture_several_photos 10, 2
        end

  It is done when the vehicle reaches its last item (landed and disarmed if
  it lands); one that ends in an endless loiter runs until stopped.
  """
  defmacro mission(name, do: block), do: build(name, block, __CALLER__)

  @doc """
  A mission from the commands of the block, named by its `name` command
  (default `"mission"`).

      back =
        mission do
          name "Return to base"
          return_home_and_land()
        end
  """
  defmacro mission(do: block), do: build("mission", block, __CALLER__)

  defp build(name, block, caller) do
    words = words()
    body = collect(block, 0, words, caller)

    quote do
      Dolphin.Mission.new(unquote(name), (fn -> unquote(body) end).())
    end
  end

  defp words do
    Command.__info__(:functions)
    |> Enum.reject(fn {name, _} -> String.starts_with?(Atom.to_string(name), "__") end)
    |> Enum.group_by(fn {name, _} -> name end, fn {_, arity} -> arity end)
  end

  # A block whose every expression counts: statements in order, the values of
  # the non-match ones gathered into a list.
  defp collect(block, depth, words, caller) do
    acc = Macro.var(:"dolphin_mission_acc_#{depth}", __MODULE__)
    exprs = Dolphin.DSL.Expand.exprs(block)

    steps =
      Enum.map(exprs, fn
        {:=, meta, [lhs, rhs]} ->
          {:=, meta, [lhs, rewrite(rhs, words, caller)]}

        expr ->
          value = value(expr, depth + 1, words, caller)
          source = Macro.to_string(expr)

          quote do
            unquote(acc) = Dolphin.DSL.Mission.__collect__(unquote(acc), unquote(value), unquote(source))
          end
      end)

    quote do
      unquote(acc) = []
      unquote_splicing(steps)
      Enum.reverse(unquote(acc))
    end
  end

  # The value of one expression of a collected block: control forms collect
  # their bodies too.
  defp value({kind, meta, [condition, clauses]}, depth, words, caller) when kind in [:if, :unless] and is_list(clauses) do
    clauses = Enum.map(clauses, fn {key, body} -> {key, collect(body, depth, words, caller)} end)
    {kind, meta, [rewrite(condition, words, caller), clauses]}
  end

  defp value({:case, meta, [expr, [do: clauses]]}, depth, words, caller) do
    {:case, meta, [rewrite(expr, words, caller), [do: collect_clauses(clauses, depth, words, caller)]]}
  end

  defp value({:cond, meta, [[do: clauses]]}, depth, words, caller) do
    clauses = Enum.map(clauses, fn {:->, m, [[c], body]} -> {:->, m, [[rewrite(c, words, caller)], collect(body, depth, words, caller)]} end)
    {:cond, meta, [[do: clauses]]}
  end

  defp value({:for, meta, args} = expr, depth, words, caller) when is_list(args) do
    {generators, opts} = Enum.split(args, -1)

    case opts do
      [opts] when is_list(opts) ->
        if Keyword.has_key?(opts, :do) and not Keyword.has_key?(opts, :reduce) and not Keyword.has_key?(opts, :into) do
          opts = Keyword.update!(opts, :do, &collect(&1, depth, words, caller))
          {:for, meta, Enum.map(generators, &rewrite(&1, words, caller)) ++ [rewrite_keyword(opts, [:do], words, caller)]}
        else
          rewrite(expr, words, caller)
        end

      _ ->
        rewrite(expr, words, caller)
    end
  end

  defp value({:__block__, _, _} = block, depth, words, caller), do: collect(block, depth, words, caller)
  defp value(expr, _depth, words, caller), do: rewrite(expr, words, caller)

  defp collect_clauses(clauses, depth, words, caller) do
    Enum.map(clauses, fn {:->, m, [head, body]} -> {:->, m, [head, collect(body, depth, words, caller)]} end)
  end

  defp rewrite_keyword(opts, skip, words, caller) do
    Enum.map(opts, fn {k, v} -> if k in skip, do: {k, v}, else: {k, rewrite(v, words, caller)} end)
  end

  # Rewrites the command words of Table 2 into calls of Dolphin.Mission.Command,
  # leaving patterns alone.
  defp rewrite({:=, meta, [lhs, rhs]}, words, caller), do: {:=, meta, [lhs, rewrite(rhs, words, caller)]}
  defp rewrite({:<-, meta, [lhs, rhs]}, words, caller), do: {:<-, meta, [lhs, rewrite(rhs, words, caller)]}
  defp rewrite({:->, meta, [heads, body]}, words, caller), do: {:->, meta, [heads, rewrite(body, words, caller)]}

  defp rewrite({:fn, meta, clauses}, words, caller) do
    clauses = Enum.map(clauses, fn {:->, m, [heads, body]} -> {:->, m, [heads, fn_body(body, words, caller)]} end)
    {:fn, meta, clauses}
  end

  defp rewrite({:&, meta, [{:/, m2, [{name, m3, ctx}, arity]}]}, words, caller) when is_atom(ctx) and is_integer(arity) do
    if Map.has_key?(words, name) do
      check_arity!(name, arity, words, m3, caller)
      {:&, meta, [{:/, m2, [{{:., m3, [Command, name]}, [no_parens: true] ++ m3, []}, arity]}]}
    else
      {:&, meta, [{:/, m2, [{name, m3, ctx}, arity]}]}
    end
  end

  # `position |> go_pos()`: the piped value is the first argument.
  defp rewrite({:|>, meta, [lhs, {name, m, args}]}, words, caller) when is_atom(name) and is_list(args) do
    lhs = rewrite(lhs, words, caller)
    args = Enum.map(args, &rewrite(&1, words, caller))

    if Map.has_key?(words, name) do
      check_arity!(name, length(args) + 1, words, m, caller)
      {:|>, meta, [lhs, {{:., m, [Command, name]}, m, args}]}
    else
      {:|>, meta, [lhs, {name, m, args}]}
    end
  end

  # A mission's own fence (Dolphin.DSL.Fence): its block is the fence's words.
  defp rewrite({:fence, _meta, [[do: block]]}, _words, caller), do: Dolphin.DSL.Fence.build(block, caller)

  defp rewrite({name, meta, args}, words, caller) when is_atom(name) and is_list(args) do
    args = Enum.map(args, &rewrite(&1, words, caller))

    if Map.has_key?(words, name) and not special_form?(name) do
      check_arity!(name, length(args), words, meta, caller)
      check_durations!(name, args, meta, caller)
      {{:., meta, [Command, name]}, meta, args}
    else
      {name, meta, args}
    end
  end

  # A bare word (`return_home_and_land` without parentheses) is a call unless it is a variable.
  defp rewrite({name, meta, ctx} = var, words, caller) when is_atom(name) and is_atom(ctx) do
    if 0 in Map.get(words, name, []) and not Macro.Env.has_var?(caller, {name, ctx}),
      do: {{:., meta, [Command, name]}, meta, []},
      else: var
  end

  defp rewrite({call, meta, args}, words, caller) when is_list(args),
    do: {rewrite(call, words, caller), meta, Enum.map(args, &rewrite(&1, words, caller))}

  defp rewrite({a, b}, words, caller), do: {rewrite(a, words, caller), rewrite(b, words, caller)}
  defp rewrite(list, words, caller) when is_list(list), do: Enum.map(list, &rewrite(&1, words, caller))
  defp rewrite(other, _words, _caller), do: other

  defp special_form?(name), do: name in [:__block__, :__aliases__, :., :fn, :&, :=, :^, :"::", :quote, :unquote]

  # In a fn body only the last value is returned: a command before it would be lost.
  defp fn_body({:__block__, meta, exprs}, words, caller) do
    {init, [last]} = Enum.split(exprs, -1)

    for {name, m, args} <- init, is_atom(name), is_list(args), Map.has_key?(words, name) do
      raise CompileError,
        file: caller.file,
        line: m[:line] || caller.line,
        description:
          "the value of #{name}/#{length(args)} is thrown away: a fn returns only its last value. " <>
            "Return a list ([cmd1, cmd2]) or use for"
    end

    {:__block__, meta, Enum.map(init, &rewrite(&1, words, caller)) ++ [rewrite(last, words, caller)]}
  end

  defp fn_body(body, words, caller), do: rewrite(body, words, caller)

  defp check_arity!(name, arity, words, meta, caller) do
    arities = Map.fetch!(words, name)

    unless arity in arities do
      raise CompileError,
        file: caller.file,
        line: meta[:line] || caller.line,
        description: "mission command #{name} takes #{Enum.map_join(Enum.sort(arities), " or ", &Integer.to_string/1)} arguments, not #{arity}"
    end
  end

  defp check_durations!(name, args, meta, caller) do
    for i <- Map.get(@time_args, name, []), {fun, _, [_]} <- [Enum.at(args, i)], fun in @duration_values do
      raise CompileError,
        file: caller.file,
        line: meta[:line] || caller.line,
        description:
          "#{name} takes seconds as a plain number, as in the report (#{name} 30); " <>
            "#{fun}(...) is a duration in milliseconds"
    end

    :ok
  end

  @doc false
  # Adds the value of one expression of a mission block to the accumulated
  # commands (in reverse order).
  def __collect__(acc, %Command{} = command, _source), do: [command | acc]
  def __collect__(acc, %Dolphin.Fence{} = fence, _source), do: [fence | acc]
  def __collect__(acc, %Dolphin.Mission{commands: commands}, _source), do: Enum.reverse(commands, acc)
  def __collect__(acc, nil, _source), do: acc
  def __collect__(acc, list, source) when is_list(list), do: Enum.reduce(list, acc, &__collect__(&2, &1, source))

  def __collect__(_acc, other, source) do
    raise ArgumentError,
          "in a mission block, `#{source}` gave #{inspect(other)}, which is not a mission command " <>
            "(a command, a list of them, a mission or nil). To run code for its effect write `_ = ...`; " <>
            "Enum.each returns :ok: use for or Enum.map"
  end
end
