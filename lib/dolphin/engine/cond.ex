defmodule Dolphin.Engine.Cond do
  @moduledoc """
  A condition: a closure returning a truthy or falsy value, with the source
  text it was written as (for events and errors).

      iex> c = Dolphin.Engine.Cond.new(fn -> 1 + 1 == 2 end, source: "1 + 1 == 2")
      iex> Dolphin.Engine.Cond.evaluate(c)
      {:ok, true}

  The script macros (`until(t, battery(v1) < 0.3)`) build these from the
  expression. The engine evaluates a condition when its task starts, again
  whenever something it read changes — the state of a vehicle it read
  (`battery/1`, `position/1`, ... record what they read while a condition is
  evaluated), a signal (`poll/1`) — and on a slow tick for conditions on
  anything else (time). A closure returning another closure or condition is
  evaluated through it, so `until(t, my_condition)` works with a variable.
  """

  @enforce_keys [:fun]
  defstruct fun: nil, source: "condition", meta: %{}

  @type t :: %__MODULE__{fun: (() -> term()), source: String.t(), meta: map()}

  @deps :"$dolphin_deps"

  @doc "A condition from a 0-arity function; options `:source` (text), `:meta`."
  @spec new((() -> term()), keyword()) :: t()
  def new(fun, opts \\ [])
  def new(fun, opts) when is_function(fun, 0), do: %__MODULE__{fun: fun, source: Keyword.get(opts, :source, "condition"), meta: Map.new(Keyword.get(opts, :meta, %{}))}
  def new(other, _opts), do: raise(ArgumentError, "a condition is a function of no arguments, got: #{inspect(other)}")

  @doc "Converts a condition, a 0-arity function or a `condition` task to a `Cond`."
  @spec from(t() | (() -> term()) | Dolphin.Engine.Condition.t()) :: t()
  def from(%__MODULE__{} = c), do: c
  def from(%Dolphin.Engine.Condition{cond: c}), do: c
  def from(fun) when is_function(fun, 0), do: new(fun)
  def from(other), do: raise(ArgumentError, "not a condition: #{inspect(other)} (use a boolean expression, a function of no arguments or condition/1)")

  @doc """
  Evaluates a condition: `{:ok, boolean}`, or `{:error, exception, stacktrace}`
  if it raised. What it read is recorded (see `track/1`).
  """
  @spec evaluate(t()) :: {:ok, boolean()} | {:error, Exception.t(), Exception.stacktrace()}
  def evaluate(%__MODULE__{} = c) do
    outer = Process.get(@deps)
    if outer == nil, do: Process.put(@deps, MapSet.new())

    try do
      {:ok, truthy(value(c.fun.()))}
    rescue
      e -> {:error, e, __STACKTRACE__}
    catch
      kind, reason -> {:error, %ErlangError{original: {kind, reason}}, __STACKTRACE__}
    after
      if outer == nil, do: Process.delete(@deps)
    end
  end

  defp value(f) when is_function(f, 0), do: value(f.())
  defp value(%__MODULE__{fun: f}), do: value(f.())
  defp value(%Dolphin.Engine.Condition{cond: c}), do: value(c)
  defp value(v), do: v

  defp truthy(v), do: v != nil and v != false

  @doc """
  Called by what conditions read (vehicle state, signals): true when a
  condition is being evaluated in this process (the reader then keeps a
  subscription and a cache in the evaluating process). `dep` is recorded.
  """
  @spec track(term()) :: boolean()
  def track(dep) do
    case Process.get(@deps) do
      nil ->
        false

      deps ->
        Process.put(@deps, MapSet.put(deps, dep))
        true
    end
  end

  defimpl Inspect do
    def inspect(%{source: s}, _opts), do: "#Cond<#{s}>"
  end
end
