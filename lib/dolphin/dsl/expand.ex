defmodule Dolphin.DSL.Expand do
  @moduledoc false
  # What the macros of Dolphin.DSL expand to, built at compile time: a
  # condition becomes a `Dolphin.Engine.Cond` of a closure in three-valued
  # logic (with its source text and script line), an action a closure, and a
  # statement records its script line first.

  # The line goes first so that an error whose stack has lost the script's
  # frame (raised in another process, say) is still reported at it.
  @spec at_line(Macro.t(), Macro.Env.t()) :: Macro.t()
  def at_line(call, caller) do
    quote do
      Dolphin.Script.Statements.__line__(unquote(caller.line))
      unquote(call)
    end
  end

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
    quote do
      Dolphin.Engine.Cond.new(fn -> unquote(logic(c)) end, source: unquote(Macro.to_string(c)), meta: unquote(meta(caller)))
    end
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
  @spec logic(Macro.t()) :: Macro.t()
  def logic({op, _, [a, b]}) when op in [:and, :&&] do
    quote do
      case Dolphin.Engine.Cond.truth(unquote(logic(a))) do
        false -> false
        left -> Dolphin.Engine.Cond.both(left, unquote(logic(b)))
      end
    end
  end

  def logic({op, _, [a, b]}) when op in [:or, :||] do
    quote do
      case Dolphin.Engine.Cond.truth(unquote(logic(a))) do
        true -> true
        left -> Dolphin.Engine.Cond.either(left, unquote(logic(b)))
      end
    end
  end

  def logic({op, _, [a]}) when op in [:not, :!], do: quote(do: Dolphin.Engine.Cond.negate(unquote(logic(a))))

  # `x == nil`, `x != nil` ask whether a value is known: a plain test.
  def logic({op, _, [a, b]} = test) when op in @equality and (a == nil or b == nil), do: test

  def logic({op, _, [a, b]}) when op in @comparisons,
    do: quote(do: Dolphin.Engine.Cond.compare(unquote(op), unquote(operand(a)), unquote(operand(b))))

  def logic({:in, _, [a, b]}), do: quote(do: Dolphin.Engine.Cond.member(unquote(operand(a)), unquote(b)))

  def logic({:__block__, meta, [_ | _] = exprs}) do
    {init, [last]} = Enum.split(exprs, -1)
    {:__block__, meta, init ++ [logic(last)]}
  end

  def logic(leaf), do: quote(do: Dolphin.Engine.Cond.truth(unquote(leaf)))

  # An operand of a comparison: arithmetic on an unknown value is unknown
  # (not an ArithmeticError); a nested condition keeps its unknowns.
  defp operand({op, _, [a, b]}) when op in @arithmetic,
    do: quote(do: Dolphin.Engine.Cond.arith(unquote(op), unquote(operand(a)), unquote(operand(b))))

  defp operand({:-, _, [a]}) when not is_number(a), do: quote(do: Dolphin.Engine.Cond.arith(:-, unquote(operand(a))))
  defp operand({op, _, args} = c) when op in [:and, :or, :not, :&&, :||, :!] and is_list(args), do: logic(c)
  defp operand({op, _, [_, _]} = c) when op in @comparisons, do: logic(c)
  defp operand(other), do: other
end
