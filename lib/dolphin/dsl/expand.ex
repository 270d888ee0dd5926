defmodule Dolphin.DSL.Expand do
  @moduledoc false
  # What the macros of Dolphin.DSL expand to, built at compile time: a
  # condition becomes a `Dolphin.Engine.Cond` of a function of its snapshot
  # (its readers rewritten to read the snapshot) in three-valued logic (with
  # its source text and script line), an action a closure, and a statement
  # records its script line first.

  # The line goes first so that an error whose stack has lost the script's
  # frame (raised in another process, say) is still reported at it.
  @spec at_line(Macro.t(), Macro.Env.t()) :: Macro.t()
  def at_line(call, caller) do
    quote do
      Dolphin.Script.Statements.__line__(unquote(caller.line))
      unquote(call)
    end
  end

  @doc false
  # The expressions of a `do` block, in order.
  @spec exprs(Macro.t()) :: [Macro.t()]
  def exprs({:__block__, _, exprs}), do: exprs
  def exprs(nil), do: []
  def exprs(expr), do: [expr]

  @spec action_ast(Macro.t(), Macro.t(), Macro.Env.t()) :: Macro.t()
  def action_ast(name, block, caller) do
    quote do
      Dolphin.Engine.action(fn -> unquote(block) end, name: unquote(name), meta: unquote(meta(caller)))
    end
  end

  @spec meta(Macro.Env.t()) :: Macro.t()
  def meta(caller), do: Macro.escape(%{line: caller.line, file: caller.file})

  @spec cond_ast(Macro.t(), Macro.Env.t()) :: Macro.t()
  def cond_ast(c, caller) do
    snapshot = Macro.var(:snapshot, __MODULE__)
    {body, follow, sensors} = reads(c, snapshot, caller)
    meta = if sensors == [], do: meta(caller), else: quote(do: Map.put(unquote(meta(caller)), :sensor_reads, unquote(sensors)))

    quote do
      Dolphin.Engine.Cond.new(fn unquote(snapshot) -> unquote(logic(body, snapshot)) end,
        source: unquote(Macro.to_string(c)),
        meta: unquote(meta),
        follow: unquote(follow)
      )
    end
  end

  # The language's readers, as a condition's expression calls them (imported
  # from Dolphin.DSL), and their snapshot versions in Dolphin.Engine.Snapshot.
  @readers [
    battery: 1,
    position: 1,
    altitude: 1,
    relative_altitude: 1,
    mode: 1,
    armed?: 1,
    connected?: 1,
    mission_progress: 1,
    poll: 1,
    poll: 2
  ]

  @sensor_readers Dolphin.DSL.Sensors.readers()

  # Modules whose functions read nothing a condition follows: calling them
  # hides no read (a reader in a `fn` given to them is rewritten like any).
  @plain [Kernel, Enum, Map, MapSet, List, Keyword, Tuple, String, Integer, Float, Access, Stream, Range]

  # The condition with its readers rewritten to read `snapshot`, and whether
  # it calls functions that may read what the rewriting cannot see (a
  # script's anonymous function, a module's own function, another
  # module's): such a condition is re-evaluated on the changes of the
  # vehicles its task flies too (Dolphin.Engine.Cond, `follow`).
  defp reads(c, snapshot, caller) do
    {body, {follow, sensors}} =
      Macro.prewalk(c, {false, []}, fn
        {name, meta, args} = call, {follow, sensors} when is_atom(name) and is_list(args) ->
          arity = length(args)

          cond do
            {name, arity} in @readers and imported?(caller, name, arity, Dolphin.DSL) ->
              {{{:., meta, [Dolphin.Engine.Snapshot, name]}, meta, [snapshot | args]}, {follow, sensors}}

            # A sensor's reader reads the sensor declared (a declaration reads nothing).
            {name, arity} in @sensor_readers and {:macro, Dolphin.DSL.Sensors} in Macro.Env.lookup_import(caller, {name, arity}) ->
              case Dolphin.DSL.Sensors.rewrite(name, args, snapshot, caller) do
                nil -> {call, {follow, sensors}}
                read -> {read, {follow, sensors ++ sensor_read(args, caller)}}
              end

            # Operators, special forms and the language's words read nothing hidden.
            Macro.operator?(name, arity) or Macro.special_form?(name, arity) or name in [:fn, :->, :__block__] ->
              {call, {follow, sensors}}

            true ->
              {call, {follow or not Enum.any?(Macro.Env.lookup_import(caller, {name, arity}), fn {_, m} -> plain?(m) end), sensors}}
          end

        {{:., _, [module, _fun]}, meta, _} = call, {follow, sensors} ->
          case Macro.expand(module, caller) do
            module when is_atom(module) -> {call, {follow or not plain?(module), sensors}}
            # A field of a value (`position(v).h`) reads nothing hidden; a call through a variable may.
            _value -> {call, {follow or not Keyword.get(meta, :no_parens, false), sensors}}
          end

        {{:., _, [_fun]}, _, _} = call, {_follow, sensors} ->
          {call, {true, sensors}}

        other, acc ->
          {other, acc}
      end)

    {body, follow, Enum.uniq(sensors)}
  end

  # A sensor read on a vehicle named by a variable or an id, as `{vehicle,
  # sensor}` for the condition's `sensor_threshold` event; a vehicle
  # computed otherwise is not known before the condition runs.
  defp sensor_read([v, name | _], caller) when is_atom(name) do
    case v do
      {var, _, context} when is_atom(var) and is_atom(context) -> [quote(do: {unquote(v), unquote(Macro.escape(Dolphin.DSL.Sensors.declared(caller)[name]))})]
      id when is_integer(id) -> [quote(do: {unquote(id), unquote(Macro.escape(Dolphin.DSL.Sensors.declared(caller)[name]))})]
      _ -> []
    end
  end

  defp sensor_read(_args, _caller), do: []

  defp imported?(caller, name, arity, module), do: {:function, module} in Macro.Env.lookup_import(caller, {name, arity})

  # Elixir's own modules above, Erlang's (`:math`), Dolphin's.
  defp plain?(module) when module in @plain, do: true

  defp plain?(module) do
    name = Atom.to_string(module)
    String.starts_with?(name, "Elixir.Dolphin.") or not String.starts_with?(name, "Elixir.")
  end

  # `one_of`/`all_of` clauses `condition -> task` as `{cond, task}` pairs.
  @spec branches(Macro.t(), atom(), Macro.Env.t()) :: [Macro.t()]
  def branches(clauses, what, caller) when is_list(clauses) do
    Enum.map(clauses, fn
      {:->, _, [[c], t]} ->
        quote(do: {unquote(cond_ast(c, caller)), unquote(t)})

      other ->
        raise ArgumentError, "#{what} takes clauses `condition -> task`, got: #{Macro.to_string(other)}"
    end)
  end

  def branches(other, what, _caller),
    do: raise(ArgumentError, "#{what} takes clauses `condition -> task` in its do block, got: #{Macro.to_string(other)}")

  @comparisons [:<, :>, :<=, :>=, :==, :!=, :===, :!==]
  @equality [:==, :!=, :===, :!==]
  @arithmetic [:+, :-, :*, :/]

  # A condition's expression in three-valued logic (see "Unknown values" in
  # Dolphin.DSL's moduledoc and Dolphin.Engine.Cond): its boolean skeleton
  # (and, or, not, &&, ||, !, comparisons, the last expression of a block) is
  # rewritten; anything else is a leaf, evaluated as written, nil reading as
  # unknown. `and`/`or` keep Elixir's short-circuit where the left side
  # decides alone.
  # `snapshot`: the variable of the condition's snapshot, through which a
  # leaf that is itself a condition (or a function) is evaluated; nil where
  # there is none (`filter/2`'s function).
  @spec logic(Macro.t(), Macro.t()) :: Macro.t()
  def logic(expr, snapshot \\ nil)

  def logic({op, _, [a, b]}, snapshot) when op in [:and, :&&] do
    quote do
      case Dolphin.Engine.Cond.truth(unquote(logic(a, snapshot))) do
        false -> false
        left -> Dolphin.Engine.Cond.both(left, unquote(logic(b, snapshot)))
      end
    end
  end

  def logic({op, _, [a, b]}, snapshot) when op in [:or, :||] do
    quote do
      case Dolphin.Engine.Cond.truth(unquote(logic(a, snapshot))) do
        true -> true
        left -> Dolphin.Engine.Cond.either(left, unquote(logic(b, snapshot)))
      end
    end
  end

  def logic({op, _, [a]}, snapshot) when op in [:not, :!], do: quote(do: Dolphin.Engine.Cond.negate(unquote(logic(a, snapshot))))

  # `x == nil`, `x != nil` ask whether a value is known: a plain test.
  def logic({op, _, [a, b]} = test, _snapshot) when op in @equality and (a == nil or b == nil), do: test

  def logic({op, _, [a, b]}, snapshot) when op in @comparisons,
    do: quote(do: Dolphin.Engine.Cond.compare(unquote(op), unquote(operand(a, snapshot)), unquote(operand(b, snapshot))))

  def logic({:in, _, [a, b]}, snapshot), do: quote(do: Dolphin.Engine.Cond.member(unquote(operand(a, snapshot)), unquote(b)))

  def logic({:__block__, meta, [_ | _] = exprs}, snapshot) do
    {init, [last]} = Enum.split(exprs, -1)
    {:__block__, meta, init ++ [logic(last, snapshot)]}
  end

  def logic(leaf, nil), do: quote(do: Dolphin.Engine.Cond.truth(unquote(leaf)))
  def logic(leaf, snapshot), do: quote(do: Dolphin.Engine.Cond.truth(unquote(leaf), unquote(snapshot)))

  # An operand of a comparison: arithmetic on an unknown value is unknown
  # (not an ArithmeticError); a nested condition keeps its unknowns.
  defp operand({op, _, [a, b]}, snapshot) when op in @arithmetic,
    do: quote(do: Dolphin.Engine.Cond.arith(unquote(op), unquote(operand(a, snapshot)), unquote(operand(b, snapshot))))

  defp operand({:-, _, [a]}, snapshot) when not is_number(a), do: quote(do: Dolphin.Engine.Cond.arith(:-, unquote(operand(a, snapshot))))
  defp operand({op, _, args} = c, snapshot) when op in [:and, :or, :not, :&&, :||, :!] and is_list(args), do: logic(c, snapshot)
  defp operand({op, _, [_, _]} = c, snapshot) when op in @comparisons, do: logic(c, snapshot)
  defp operand(other, _snapshot), do: other
end
