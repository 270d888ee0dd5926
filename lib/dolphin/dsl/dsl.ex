defmodule Dolphin.DSL do
  @moduledoc """
  The vocabulary of scripts (`../shared/DSL.md`), imported by
  `use Dolphin.Script` together with `Dolphin.DSL.Values` (locations, areas,
  units) and the `mission` block of `Dolphin.DSL.Mission`.

  Every word is sugar: functions delegate to `Dolphin.Engine` (tasks),
  `Dolphin.Fleet` (vehicles) and `Dolphin.Script` (statements); the macros
  only turn expressions into closures (conditions, `action` bodies, loop
  bodies) and record the script line.

  | word | plain function |
  | --- | --- |
  | `pick(opts)`, `release(set)` | `Dolphin.Script.pick/1`, `Dolphin.Script.release/1` |
  | `union/2`, `difference/2`, `intersection/2`, `filter/2` | `Dolphin.Fleet.VehicleSet` |
  | `battery(v)`, `position(v)`, `altitude(v)`, `relative_altitude(v)`, `mode(v)`, `armed?(v)`, `connected?(v)`, `mission_progress(v)` | `Dolphin.Fleet.state/2` |
  | `set_connection_timeout(t)`, `set_connection_timeout(set, t)` | `Dolphin.Script.set_connection_timeout/1,2` |
  | `idle(d)`, `on(t, set)`, `during(d, t)`, `watch(t, on_error: h)`, `named(t, name)`, `t1 >>> t2`, `t1 \\|\\|\\| t2` | `Dolphin.Engine` |
  | `action do ... end`, `condition(c)`, `until(t, c)`, `wait_for(c)`, `wait_for(c, then: t)`, `one_of do c -> t ... end`, `all_of do ... end` | `Dolphin.Engine` with a `Dolphin.Engine.Cond` |
  | `execute(t)`, `execute(%{v1 => t1, _: t2})`, `execute action do ... end` | `Dolphin.Script.execute/1` |
  | `forever do ... end`, `forever(state, fn s -> ... end)`, `repeat(n) do ... end` | `Dolphin.Script.forever/1,2`, `Dolphin.Script.repeat/2` |
  | `message`, `post`, `consume`, `poll`, `pause`, `halt`, `ask`, `send_message` | `Dolphin.Script` |

  Conditions are ordinary expressions — `battery(v1) < 0.3`, `poll(:go)`,
  `connected?(v) and mode(v) == :guided` — re-evaluated whenever what they
  read changes.

  ## Unknown values

  What a vehicle has not reported yet reads as `nil`: `battery/1`,
  `position/1`, `altitude/1`, `relative_altitude/1`, `mode/1` and
  `mission_progress/1` until the first report, `distance/2`, `near?/3` and
  `contains?/2` of an unknown position, arithmetic on an unknown value. A
  condition that depends on an unknown value is **not met**, and reading one
  never raises:

    * a comparison (`<`, `<=`, `>`, `>=`, `==`, `!=`, `===`, `!==`, `in`)
      with an unknown side is unknown — `battery(v) >= 0.9` does not hold before
      the battery is reported (Elixir alone would say `nil >= 0.9` is true);
    * `not`/`!` of unknown is unknown: `not (battery(v) < 0.3)` does not hold
      either;
    * `and`/`&&`, `or`/`||` follow three-valued logic: `false and unknown`
      is false, `true or unknown` is true, anything else with an unknown
      side is unknown; `connected?(v) == false or battery(v) < 0.2` holds as
      soon as the vehicle is lost, whatever its battery;
    * any other expression is unknown when its value is `nil`;
    * a condition holds only when its value is true; unknown is treated as
      false, so `wait_for`, `until`, `one_of` and `all_of` keep waiting.

  `x == nil` and `x != nil` (a literal `nil`) ask whether a value is known:
  `wait_for(position(v) != nil)` waits for the first position. The same
  rules apply to the function given to `filter/2` when it is written in
  place (`filter(vs, fn v -> battery(v) > 0.5 end)` leaves out the
  vehicles whose battery is unknown). Functions the condition calls are
  evaluated as Elixir: the rules apply to the condition's own expression.

  `>>>` binds tighter than `|||`, as `>>` and `|` do in Dolphin:
  `a >>> b ||| c` is `(a >>> b) ||| c`.
  """

  alias Dolphin.Engine
  alias Dolphin.Fleet
  alias Dolphin.Fleet.VehicleSet

  # --- vehicles ---

  @doc "Picks vehicles (blocks; see `Dolphin.Fleet`): `count`, `type`, `payload`, `region`, `id`, `timeout`."
  defmacro pick(opts \\ []), do: at_line(quote(do: Dolphin.Script.pick(unquote(opts))), __CALLER__)
  @doc "Makes vehicles available again: a set or a list of sets."
  defdelegate release(sets), to: Dolphin.Script
  @doc "Vehicles in either set."
  defdelegate union(a, b), to: VehicleSet
  @doc "Vehicles of `a` not in `b`."
  defdelegate difference(a, b), to: VehicleSet
  @doc "Vehicles in both sets."
  defdelegate intersection(a, b), to: VehicleSet
  @doc """
  Vehicles of `set` for which `fun` (given a one-vehicle set) is truthy. A
  `fn` written in place is a condition (see "Unknown values"): a vehicle
  whose value is unknown is left out.
  """
  defmacro filter(set, {:fn, meta, [{:->, arrow_meta, [args, body]}]}),
    do: quote(do: VehicleSet.filter(unquote(set), unquote({:fn, meta, [{:->, arrow_meta, [args, quote(do: Dolphin.Engine.Cond.met?(unquote(logic(body))))]}]})))

  defmacro filter(set, fun), do: quote(do: VehicleSet.filter(unquote(set), unquote(fun)))
  @doc "A vehicle silent for longer than `ms` is lost (its task fails); for the vehicles picked now and later."
  defdelegate set_connection_timeout(ms), to: Dolphin.Script
  @doc "The connection timeout of the vehicles of `set`."
  defdelegate set_connection_timeout(set, ms), to: Dolphin.Script

  @typedoc "A one-vehicle set (or a system id)."
  @type vehicle :: VehicleSet.t() | non_neg_integer()

  @doc "Remaining battery, 0.0..1.0 (nil until reported), of a one-vehicle set."
  @spec battery(vehicle()) :: float() | nil
  def battery(v), do: Fleet.state(v, :battery).battery
  @doc "Position (a `Dolphin.Geo.Location`, height above mean sea level) or nil until reported."
  @spec position(vehicle()) :: Dolphin.Geo.Location.t() | nil
  def position(v), do: Fleet.state(v, :position).position
  @doc "Height above mean sea level in metres, or nil until reported."
  @spec altitude(vehicle()) :: float() | nil
  def altitude(v), do: with(%{h: h} <- Fleet.state(v, :altitude).position, do: h)
  @doc "Height above home in metres, or nil until reported."
  @spec relative_altitude(vehicle()) :: float() | nil
  def relative_altitude(v), do: Fleet.state(v, :relative_altitude).relative_altitude
  @doc "Flight mode (`:guided`, `:auto`, ...) or nil until reported."
  @spec mode(vehicle()) :: atom() | nil
  def mode(v), do: Fleet.state(v, :mode).mode
  @doc "Whether the vehicle is armed."
  @spec armed?(vehicle()) :: boolean()
  def armed?(v), do: Fleet.state(v, :armed?).armed?
  @doc "Whether the vehicle is heard (not lost)."
  @spec connected?(vehicle()) :: boolean()
  def connected?(v), do: Fleet.state(v, :connected?).connected?
  @doc """
  `{reached, total}`: the last mission item reached (0 before the first) and
  the items of the mission, counted from its last upload; nil until the
  vehicle reports its mission. Tuples compare element by element:
  `mission_progress(v) >= {3, 0}` holds once item 3 is reached.
  """
  @spec mission_progress(vehicle()) :: {non_neg_integer(), non_neg_integer()} | nil
  def mission_progress(v), do: Fleet.state(v, :mission_progress).mission_progress

  # --- tasks ---

  @doc "A task that completes after `d` ms."
  defdelegate idle(d), to: Engine
  @doc "`t` restricted to the vehicles of `set`."
  defdelegate on(t, set), to: Engine
  @doc "`t` for at most `d` ms."
  defdelegate during(d, t), to: Engine
  @doc "`t` with an error handler: `on_error: :ignore | :propagate | fn failure -> ... end`."
  defdelegate watch(t, opts), to: Engine
  @doc "A task with a name."
  defdelegate named(t, name), to: Engine

  @doc "Sequence: `t1` then `t2`."
  @spec term() >>> term() :: Dolphin.Engine.Sequence.t()
  def t1 >>> t2, do: Engine.sequence([t1, t2])
  @doc "Concurrency: `t1` and `t2` at the same time."
  @spec term() ||| term() :: Dolphin.Engine.Concurrent.t()
  def t1 ||| t2, do: Engine.concurrent([t1, t2])

  @doc "A task running the block once (in its own process)."
  defmacro action(do: block), do: action_ast(nil, block, __CALLER__)
  @doc "A named `action`."
  defmacro action(name, do: block), do: action_ast(name, block, __CALLER__)

  @doc "A task that completes when `c` holds."
  defmacro condition(c), do: quote(do: Dolphin.Engine.condition(unquote(cond_ast(c, __CALLER__)), meta: unquote(meta(__CALLER__))))

  @doc "`t` until `c` holds."
  defmacro until(t, c), do: quote(do: Dolphin.Engine.until(unquote(t), unquote(cond_ast(c, __CALLER__)), meta: unquote(meta(__CALLER__))))

  @doc "Waits until `c` holds (`wait_for(c)`), then runs `then:` (`wait_for(c, then: t)`)."
  defmacro wait_for(c), do: quote(do: Dolphin.Engine.wait_for(unquote(cond_ast(c, __CALLER__)), nil, meta: unquote(meta(__CALLER__))))

  defmacro wait_for(c, opts) do
    case opts do
      [then: t] -> quote(do: Dolphin.Engine.wait_for(unquote(cond_ast(c, __CALLER__)), unquote(t), meta: unquote(meta(__CALLER__))))
      _ -> raise ArgumentError, "wait_for/2 takes `then: task`, got: #{Macro.to_string(opts)}"
    end
  end

  @doc "The first branch whose condition holds runs: `one_of do c1 -> t1; c2 -> t2 end`."
  defmacro one_of(do: clauses), do: quote(do: Dolphin.Engine.one_of(unquote(branches(clauses, :one_of, __CALLER__)), meta: unquote(meta(__CALLER__))))

  @doc "Every branch runs once its condition holds: `all_of do c1 -> t1; c2 -> t2 end`."
  defmacro all_of(do: clauses), do: quote(do: Dolphin.Engine.all_of(unquote(branches(clauses, :all_of, __CALLER__)), meta: unquote(meta(__CALLER__))))

  # --- running ---

  @doc """
  Runs a task (or a map `%{set => task, _: task}`: each on its set, all at
  the same time) and returns when it is done; a failure stops the script.
  `execute action do ... end` means `execute(action do ... end)`.
  """
  defmacro execute(task), do: at_line(quote(do: Dolphin.Script.execute(unquote(task))), __CALLER__)

  defmacro execute({name, meta, args}, do: block) when is_atom(name) and (is_atom(args) or args == []),
    do: at_line(quote(do: Dolphin.Script.execute(unquote({name, meta, [[do: block]]}))), __CALLER__)

  defmacro execute(other, do: _block),
    do: raise(ArgumentError, "execute with a do block takes a word such as `action`, got: #{Macro.to_string(other)}")

  @doc "Runs the block for ever."
  defmacro forever(do: block), do: quote(do: Dolphin.Script.forever(fn -> unquote(block) end))
  @doc "Runs `fun` for ever, each round given what the previous one returned (starting with `state`)."
  defdelegate forever(state, fun), to: Dolphin.Script
  @doc "Runs the block `n` times."
  defmacro repeat(n, do: block), do: quote(do: Dolphin.Script.repeat(unquote(n), fn -> unquote(block) end))

  @doc "An operator log line."
  defdelegate message(text), to: Dolphin.Script
  @doc "Posts `value` to signal `key`."
  defdelegate post(key, value), to: Dolphin.Script
  @doc "Consumes `value` from signal `key`; true if it was there."
  defdelegate consume(key, value), to: Dolphin.Script
  @doc "Whether signal `key` has a value."
  defdelegate poll(key), to: Dolphin.Script
  @doc "Whether signal `key` has a value satisfying `fun`."
  defdelegate poll(key, fun), to: Dolphin.Script
  @doc "Pauses the script for `d` ms."
  defdelegate pause(d), to: Dolphin.Script
  @doc "Stops the script with a message."
  defmacro halt(text \\ "halted"), do: at_line(quote(do: Dolphin.Script.halt(unquote(text))), __CALLER__)
  @doc "Asks the operator; returns the line typed."
  defdelegate ask(prompt), to: Dolphin.Script
  @doc "Sends a raw (MAVLink) message to the vehicles of a set."
  defdelegate send_message(set, message), to: Dolphin.Script

  # --- macro helpers ---

  defp at_line(call, caller) do
    quote do
      Dolphin.Script.__line__(unquote(caller.line))
      unquote(call)
    end
  end

  defp meta(caller), do: Macro.escape(%{line: caller.line, file: caller.file})

  defp cond_ast(c, caller) do
    quote do
      Dolphin.Engine.Cond.new(fn -> unquote(logic(c)) end, source: unquote(Macro.to_string(c)), meta: unquote(meta(caller)))
    end
  end

  @comparisons [:<, :>, :<=, :>=, :==, :!=, :===, :!==]
  @equality [:==, :!=, :===, :!==]
  @arithmetic [:+, :-, :*, :/]

  # A condition's expression in three-valued logic (see "Unknown values" in
  # the moduledoc and Dolphin.Engine.Cond): its boolean skeleton (and, or,
  # not, &&, ||, !, comparisons, the last expression of a block) is rewritten;
  # anything else is a leaf, evaluated as written, nil reading as unknown.
  # `and`/`or` keep Elixir's short-circuit where the left side decides alone.
  defp logic({op, _, [a, b]}) when op in [:and, :&&] do
    quote do
      case Dolphin.Engine.Cond.truth(unquote(logic(a))) do
        false -> false
        left -> Dolphin.Engine.Cond.both(left, unquote(logic(b)))
      end
    end
  end

  defp logic({op, _, [a, b]}) when op in [:or, :||] do
    quote do
      case Dolphin.Engine.Cond.truth(unquote(logic(a))) do
        true -> true
        left -> Dolphin.Engine.Cond.either(left, unquote(logic(b)))
      end
    end
  end

  defp logic({op, _, [a]}) when op in [:not, :!], do: quote(do: Dolphin.Engine.Cond.negate(unquote(logic(a))))

  # `x == nil`, `x != nil` ask whether a value is known: a plain test.
  defp logic({op, _, [a, b]} = test) when op in @equality and (a == nil or b == nil), do: test

  defp logic({op, _, [a, b]}) when op in @comparisons,
    do: quote(do: Dolphin.Engine.Cond.compare(unquote(op), unquote(operand(a)), unquote(operand(b))))

  defp logic({:in, _, [a, b]}), do: quote(do: Dolphin.Engine.Cond.member(unquote(operand(a)), unquote(b)))

  defp logic({:__block__, meta, [_ | _] = exprs}) do
    {init, [last]} = Enum.split(exprs, -1)
    {:__block__, meta, init ++ [logic(last)]}
  end

  defp logic(leaf), do: quote(do: Dolphin.Engine.Cond.truth(unquote(leaf)))

  # An operand of a comparison: arithmetic on an unknown value is unknown
  # (not an ArithmeticError); a nested condition keeps its unknowns.
  defp operand({op, _, [a, b]}) when op in @arithmetic,
    do: quote(do: Dolphin.Engine.Cond.arith(unquote(op), unquote(operand(a)), unquote(operand(b))))

  defp operand({:-, _, [a]}) when not is_number(a), do: quote(do: Dolphin.Engine.Cond.arith(:-, unquote(operand(a))))
  defp operand({op, _, args} = c) when op in [:and, :or, :not, :&&, :||, :!] and is_list(args), do: logic(c)
  defp operand({op, _, [_, _]} = c) when op in @comparisons, do: logic(c)
  defp operand(other), do: other

  defp action_ast(name, block, caller) do
    quote do
      Dolphin.Engine.action(fn -> unquote(block) end, name: unquote(name), meta: unquote(meta(caller)))
    end
  end

  defp branches(clauses, what, caller) when is_list(clauses) do
    Enum.map(clauses, fn
      {:->, _, [[c], t]} ->
        quote(do: {unquote(cond_ast(c, caller)), unquote(t)})

      other ->
        raise ArgumentError, "#{what} takes clauses `condition -> task`, got: #{Macro.to_string(other)}"
    end)
  end

  defp branches(other, what, _caller),
    do: raise(ArgumentError, "#{what} takes clauses `condition -> task` in its do block, got: #{Macro.to_string(other)}")
end
