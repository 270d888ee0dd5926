defmodule Dolphin.Engine.Signals do
  @moduledoc """
  Signals shared by the tasks of a script, as in Dolphin: a signal is a key
  with a set of values. `post/3` adds a value, `consume/3` removes one (and
  says whether it was there), `poll/2` says whether the key has any value,
  `poll/3` whether one satisfies a predicate.

      iex> t = Dolphin.Engine.Signals.new()
      iex> Dolphin.Engine.Signals.post(t, :area, :north)
      :ok
      iex> Dolphin.Engine.Signals.poll(t, :area, &(&1 == :north))
      true
      iex> Dolphin.Engine.Signals.consume(t, :area, :north)
      true
      iex> Dolphin.Engine.Signals.poll(t, :area)
      false

  A table is an ETS table owned by the process that made it (each script has
  its own; `Dolphin.Engine.Signals` itself is the application's default
  table). Every change is published on `Dolphin.PubSub` topic
  `{:dolphin_signals, table}`, and conditions that poll a signal are
  re-evaluated on it: a condition reads a table through its snapshot
  (`Dolphin.Engine.Snapshot.poll/2`, `Dolphin.Engine.Snapshot.signals/2`),
  which has its node's watcher follow the table; the functions here read
  the table as it is.
  """

  alias Dolphin.PubSub

  @type table :: :ets.tid() | atom()

  @doc "A new table, owned by the caller; `name` makes it a named table."
  @spec new(atom() | nil) :: table()
  def new(name \\ nil) do
    case name do
      nil -> :ets.new(__MODULE__, [:bag, :public])
      name -> :ets.new(name, [:bag, :public, :named_table])
    end
  end

  @doc "Adds `value` to signal `key`."
  @spec post(table(), term(), term()) :: :ok
  def post(table, key, value) do
    :ets.insert(table, {key, value})
    PubSub.publish({:dolphin_signals, table}, {:posted, key, value})
  end

  @doc "Removes `value` from signal `key`; true if it was there."
  @spec consume(table(), term(), term()) :: boolean()
  def consume(table, key, value) do
    spec = [{{:"$1", :"$2"}, [{:"=:=", :"$1", {:const, key}}, {:"=:=", :"$2", {:const, value}}], [true]}]

    case :ets.select_delete(table, spec) do
      0 ->
        false

      _ ->
        PubSub.publish({:dolphin_signals, table}, {:consumed, key, value})
        true
    end
  end

  @doc "Whether signal `key` has a value."
  @spec poll(table(), term()) :: boolean()
  def poll(table, key) do
    :ets.member(table, key)
  end

  @doc "Whether signal `key` has a value for which `fun` is truthy."
  @spec poll(table(), term(), (term() -> as_boolean(term()))) :: boolean()
  def poll(table, key, fun) when is_function(fun, 1) do
    Enum.any?(:ets.lookup(table, key), fn {_, v} -> fun.(v) end)
  end

  @doc "The values of signal `key`."
  @spec values(table(), term()) :: [term()]
  def values(table, key) do
    for {_, v} <- :ets.lookup(table, key), do: v
  end
end
