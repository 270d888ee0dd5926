defmodule Dolphin.Engine.OneOf do
  @moduledoc """
  `one_of([{c1, t1}, {c2, t2}, ...])`: the first branch whose condition holds
  runs and `one_of` ends as its task does; the other branches are dropped
  (their tasks never start). Conditions are first checked in order when
  `one_of` starts, so the earliest branch wins a tie.
  """
  use Dolphin.Engine.Task.Struct, branches: []
  @behaviour Dolphin.Engine.Node

  import Dolphin.Engine.Node, only: [cond_met: 2, completed: 1]

  @type t :: %__MODULE__{branches: [{Dolphin.Engine.Cond.t(), Dolphin.Engine.Task.t()}]}

  @impl true
  def kind, do: :one_of
  @impl true
  def init(%{branches: bs}), do: {[check(bs, 0)], %{branches: List.to_tuple(bs), n: length(bs)}}

  @impl true
  def handle({:checked, i, true}, s), do: {choose(s, i), s}
  def handle({:checked, i, false}, %{n: n} = s) when i + 1 < n, do: {[check(Tuple.to_list(s.branches), i + 1)], s}

  def handle({:checked, _i, false}, s),
    do: {for({{c, _}, i} <- Enum.with_index(Tuple.to_list(s.branches)), do: {:watch, i, c}), s}

  def handle({:condition, i}, s), do: {for(j <- 0..(s.n - 1), j != i, do: {:unwatch, j}) ++ choose(s, i), s}
  def handle({:finished, :chosen, result}, s), do: {[{:finish, completed(result)}], s}

  defp check(bs, i), do: {:check, i, elem(Enum.at(bs, i), 0)}

  defp choose(s, i) do
    {c, t} = elem(s.branches, i)
    [cond_met(c, i), {:start, :chosen, t}]
  end
end
