defmodule Dolphin.Engine.Cond do
  @moduledoc """
  A condition: a function of the `Dolphin.Engine.Snapshot` it reads,
  returning a truthy or falsy value, with the source text it was written as
  (for events and errors).

      iex> c = Dolphin.Engine.Cond.new(fn _snapshot -> 1 + 1 == 2 end, source: "1 + 1 == 2")
      iex> Dolphin.Engine.Cond.evaluate(c)
      {:ok, true}

  The script macros (`until(t, battery(v1) < 0.3)`) build these from the
  expression, rewriting its readers to read the snapshot
  (`Dolphin.Engine.Snapshot.battery(snapshot, v1)`). The engine evaluates a
  condition when its task starts, again whenever something it read changes
  — the state of a vehicle it read, a signal it polled: a
  `Dolphin.Engine.Watcher` (its node's, or for an `until` its run's
  conditions process's) follows those and hands the condition a snapshot
  of them — and on a slow tick for conditions on anything else (time). A
  condition returning another closure or condition is evaluated through it,
  on the same snapshot, so `until(t, my_condition)` works with a variable.

  A function of no argument is a condition too, but one whose reads nobody
  sees: it reads live data (`Dolphin.DSL.battery/1` outside a condition's
  expression reads the vehicle's source). Such a condition, and one the
  macros found calling functions they cannot see into (`follow: true`), is
  also re-evaluated on every change of the vehicles its task flies.

  ## Unknown values

  What a vehicle has not reported yet reads as `nil` (`battery/1`,
  `position/1`, `mode/1`, `mission_progress/1`, ...). In Erlang's term order
  `nil >= 0.9` is true, so the script macros compile a condition with
  three-valued logic instead of `Kernel`'s (see `Dolphin.DSL`, "Unknown
  values"), through `compare/3`, `member/2`, `arith/2,3`, `truth/1`, `negate/1`,
  `both/2` and `either/2`. Their third truth value, unknown, is
  `unknown/0`; a condition whose value is unknown is not met, exactly as
  one whose value is `false` or `nil`.

      iex> alias Dolphin.Engine.Cond
      iex> Cond.compare(:>=, nil, 0.9) == Cond.unknown()
      true
      iex> Cond.negate(Cond.compare(:<, nil, 0.3)) == Cond.unknown()
      true
      iex> Cond.either(Cond.unknown(), true)
      true
      iex> Cond.evaluate(Cond.new(fn _ -> Cond.compare(:>=, nil, 0.9) end))
      {:ok, false}
  """

  @enforce_keys [:fun]
  defstruct fun: nil, source: "condition", meta: %{}, follow: false

  @type t :: %__MODULE__{fun: (Dolphin.Engine.Snapshot.t() | nil -> term()) | (() -> term()), source: String.t(), meta: map(), follow: boolean()}

  # A private atom: no value a script computes can be mistaken for it.
  @unknown :"$dolphin_unknown"

  @doc """
  A condition from a function of the snapshot (or of no argument: see the
  module doc); options `:source` (text), `:meta`, `:follow` (also re-evaluate
  it on the changes of the vehicles its task flies; default: for a function
  of no argument only).
  """
  @spec new((Dolphin.Engine.Snapshot.t() | nil -> term()) | (() -> term()), keyword()) :: t()
  def new(fun, opts \\ [])

  def new(fun, opts) when is_function(fun, 1) or is_function(fun, 0) do
    follow = Keyword.get(opts, :follow, is_function(fun, 0))
    %__MODULE__{fun: fun, source: Keyword.get(opts, :source, "condition"), meta: Map.new(Keyword.get(opts, :meta, %{})), follow: follow}
  end

  def new(other, _opts), do: raise(ArgumentError, "a condition is a function of the snapshot (or of no arguments), got: #{inspect(other)}")

  @doc "Converts a condition, a function (of the snapshot or of no argument) or a `condition` task to a `Cond`."
  @spec from(t() | (Dolphin.Engine.Snapshot.t() | nil -> term()) | (() -> term()) | Dolphin.Engine.Condition.t()) :: t()
  def from(%__MODULE__{} = c), do: c
  def from(%Dolphin.Engine.Condition{cond: c}), do: c
  def from(fun) when is_function(fun, 0) or is_function(fun, 1), do: new(fun)
  def from(other), do: raise(ArgumentError, "not a condition: #{inspect(other)} (use a boolean expression, a function of the snapshot or of no arguments, or condition/1)")

  @doc """
  Evaluates a condition on `snapshot` (`nil`, the default: on live data):
  `{:ok, boolean}`, or `{:error, exception, stacktrace}` if it raised (or
  threw, or exited), or `{:read, read}` when it asked for a vehicle or a
  signal table that is not in the snapshot (`Dolphin.Engine.Snapshot`): the
  caller adds it and evaluates again.
  """
  @spec evaluate(t(), Dolphin.Engine.Snapshot.t() | nil) ::
          {:ok, boolean()} | {:error, Exception.t(), Exception.stacktrace()} | {:read, Dolphin.Engine.Snapshot.read()}
  def evaluate(%__MODULE__{} = c, snapshot \\ nil) do
    {:ok, truthy(value(c, snapshot))}
  rescue
    e -> {:error, e, __STACKTRACE__}
  catch
    # A reader's request (Dolphin.Engine.Snapshot): only a snapshot's readers make one.
    :throw, {:"$dolphin_read", read} when snapshot != nil -> {:read, read}
    kind, reason -> {:error, %ErlangError{original: {kind, reason}}, __STACKTRACE__}
  end

  defp value(f, snapshot) when is_function(f, 1), do: value(f.(snapshot), snapshot)
  defp value(f, snapshot) when is_function(f, 0), do: value(f.(), snapshot)
  defp value(%__MODULE__{fun: f}, snapshot), do: value(f, snapshot)
  defp value(%Dolphin.Engine.Condition{cond: c}, snapshot), do: value(c, snapshot)
  defp value(v, _snapshot), do: v

  defp truthy(v), do: v != nil and v != false and v != @unknown

  # --- three-valued logic of compiled conditions ---

  @comparisons [:<, :>, :<=, :>=, :==, :!=, :===, :!==]
  @arithmetic [:+, :-, :*, :/]

  @doc "The truth value \"unknown\" of compiled conditions: neither true nor false."
  @spec unknown() :: atom()
  def unknown, do: @unknown

  @doc "Whether a value is unknown: `nil` (not reported yet) or `unknown/0`."
  @spec unknown?(term()) :: boolean()
  def unknown?(v), do: v == nil or v == @unknown

  @doc """
  `a op b` for a comparison operator (`:<`, `:>=`, `:==`, ...), unknown when
  either side is unknown: nothing compares with a value nobody has seen.
  """
  @spec compare(atom(), term(), term()) :: boolean() | atom()
  def compare(op, a, b) when op in @comparisons do
    if unknown?(a) or unknown?(b), do: @unknown, else: apply(Kernel, op, [a, b])
  end

  @doc "`a in b`: unknown when `a` or `b` is unknown (`mode(v) in [:rtl, :land]` of an unseen mode)."
  @spec member(term(), term()) :: boolean() | atom()
  def member(a, b), do: if(unknown?(a) or unknown?(b), do: @unknown, else: Enum.member?(b, a))

  @doc "`a op b` for `:+`, `:-`, `:*`, `:/`; `nil` (unknown) when either side is unknown, instead of raising."
  @spec arith(atom(), term(), term()) :: number() | nil
  def arith(op, a, b) when op in @arithmetic do
    if unknown?(a) or unknown?(b), do: nil, else: apply(Kernel, op, [a, b])
  end

  @doc "Unary `-a`; `nil` when `a` is unknown."
  @spec arith(:-, term()) :: number() | nil
  def arith(:-, a), do: if(unknown?(a), do: nil, else: -a)

  @doc """
  The truth value of an expression in a condition: `true`, `false` or
  unknown (`nil` reads as unknown). A function or condition is evaluated
  through, on `snapshot`, as `evaluate/2` does.
  """
  @spec truth(term(), Dolphin.Engine.Snapshot.t() | nil) :: boolean() | atom()
  def truth(v, snapshot \\ nil) do
    case value(v, snapshot) do
      v when v == nil or v == @unknown -> @unknown
      false -> false
      _ -> true
    end
  end

  @doc "Negation: `not unknown` is unknown (a `not` never turns an unseen value into a met condition)."
  @spec negate(term()) :: boolean() | atom()
  def negate(v) do
    case truth(v) do
      true -> false
      false -> true
      other -> other
    end
  end

  @doc "Conjunction: false if either side is false, true if both are true, else unknown."
  @spec both(term(), term()) :: boolean() | atom()
  def both(a, b) do
    case {truth(a), truth(b)} do
      {false, _} -> false
      {_, false} -> false
      {true, true} -> true
      _ -> @unknown
    end
  end

  @doc "Disjunction: true if either side is true, false if both are false, else unknown."
  @spec either(term(), term()) :: boolean() | atom()
  def either(a, b) do
    case {truth(a), truth(b)} do
      {true, _} -> true
      {_, true} -> true
      {false, false} -> false
      _ -> @unknown
    end
  end

  @doc "Whether a truth value (see `truth/1`) is true: what `filter/2` keeps and a condition needs to be met."
  @spec met?(term()) :: boolean()
  def met?(v), do: truth(v) == true

  defimpl Inspect do
    def inspect(%{source: s}, _opts), do: "#Cond<#{s}>"
  end
end
