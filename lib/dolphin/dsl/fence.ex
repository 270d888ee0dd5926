defmodule Dolphin.DSL.Fence do
  @moduledoc """
  The `fence` block and `rally` of scripts (imported by `use
  Dolphin.Script`): where the script's vehicles may fly.

      use Dolphin.Script

      home = location(38.43462, -8.86118, 0)

      fence do
        include circle(home, 800)
        exclude polygon([location(38.4380, -8.8620, 0), location(38.4380, -8.8590, 0), location(38.4395, -8.8600, 0)])
        max_altitude 120
        min_altitude 10
        on_breach :rtl
      end

      rally [location(38.4330, -8.8600, 0)]

  At the top of a script, `fence do ... end` is the fence of every vehicle
  the script flies a mission on, from its next `execute` on (a later `fence`
  replaces it); inside a `mission` block it is that mission's own, in place
  of the script's. `rally points` sets the rally points (also a word of the
  block). The block's words: `include ZONE`, `exclude ZONE` (a zone is
  `polygon([locations])` or `circle(centre, metres)`, repeatable),
  `max_altitude METRES`, `min_altitude METRES` (above home), `on_breach
  :rtl | :land | :hold | :report` (default `:rtl`), `rally [locations]`; other
  Elixir (`for`, `if`, variables) works as in a mission block, each
  expression's value one of these words, a list of them, or nil.

  A mistake — a polygon of fewer than three corners or that crosses itself,
  a circle of no radius, an altitude band upside down, an unknown breach
  action — raises `ArgumentError` at the block's line; the pre-flight check
  then refuses what the fence forbids (`Dolphin.Check`), before anything
  flies.
  """

  @words [:include, :exclude, :max_altitude, :min_altitude, :on_breach, :rally]

  @doc """
  The fence of the block (a `%Dolphin.Fence{}`), made the script's fence:
  the vehicles its missions fly from the next `execute` on have it
  (a mission's own fence replaces it).
  """
  defmacro fence(do: block) do
    Dolphin.DSL.Expand.at_line(quote(do: Dolphin.Script.Statements.fence(unquote(build(block, __CALLER__)))), __CALLER__)
  end

  @doc """
  The least separation the script's vehicles are held to: `horizontal`
  metres across or `vertical` metres in height (default 20 and 10). Before
  anything flies, two of them closer than both at once in the dry run,
  while one flies, is an error at the line of the later task, with when and
  where; in flight the separation monitor (`Dolphin.Separation`) holds the
  later task's vehicle before it would come that close.
  """
  defmacro min_separation(horizontal, vertical) do
    Dolphin.DSL.Expand.at_line(quote(do: Dolphin.Script.Statements.min_separation(unquote(horizontal), unquote(vertical))), __CALLER__)
  end

  @doc "Sets the rally points of the script's fence: locations a vehicle sent home may return to instead."
  defmacro rally(points) do
    Dolphin.DSL.Expand.at_line(quote(do: Dolphin.Script.Statements.rally(unquote(points))), __CALLER__)
  end

  @doc false
  # The expression that makes the fence of a block (no more: the mission
  # block uses it for a mission's own fence).
  @spec build(Macro.t(), Macro.Env.t()) :: Macro.t()
  def build(block, caller) do
    clauses = Enum.map(Dolphin.DSL.Expand.exprs(block), &clause(&1, caller))

    quote do
      Dolphin.DSL.Fence.__build__(unquote(clauses))
    end
  end

  defp clause({word, _meta, [arg]}, _caller) when word in @words, do: quote(do: {unquote(word), unquote(arg)})

  defp clause({word, meta, args}, caller) when word in @words and is_list(args) do
    raise CompileError, file: caller.file, line: meta[:line] || caller.line, description: "#{word} in a fence block takes one argument, not #{length(args)}"
  end

  defp clause({kind, meta, [condition, clauses]}, caller) when kind in [:if, :unless] and is_list(clauses),
    do: {kind, meta, [condition, Enum.map(clauses, fn {key, body} -> {key, many(body, caller)} end)]}

  defp clause({:for, meta, args}, caller) when is_list(args) do
    {generators, [opts]} = Enum.split(args, -1)
    {:for, meta, generators ++ [Keyword.update!(opts, :do, &many(&1, caller))]}
  end

  defp clause(other, _caller), do: other

  defp many({:__block__, meta, exprs}, caller), do: {:__block__, meta, [Enum.map(exprs, &clause(&1, caller))]}
  defp many(expr, caller), do: clause(expr, caller)

  @doc false
  # A fence from the values of a block's expressions: `{word, value}`
  # clauses, lists of them, nils.
  @spec __build__(list()) :: Dolphin.Fence.t()
  def __build__(values) do
    clauses = values |> List.flatten() |> Enum.reject(&is_nil/1)

    case Enum.reject(clauses, &match?({word, _} when word in @words, &1)) do
      [] ->
        # Zones add up, in order; of the rest the last said counts.
        {zones, settings} = Enum.split_with(clauses, fn {word, _} -> word in [:include, :exclude] end)
        Dolphin.Fence.new!(zones ++ (settings |> Enum.reverse() |> Enum.uniq_by(&elem(&1, 0))))

      [other | _] ->
        raise ArgumentError, "in a fence block, #{inspect(other)} is not one of its words (#{Enum.map_join(@words, ", ", &Atom.to_string/1)})"
    end
  end
end
