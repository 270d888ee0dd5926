defmodule Dolphin.Engine.AllOf do
  @moduledoc """
  `all_of([{c1, t1}, {c2, t2}, ...])`: every branch waits for its condition
  and then runs its task, independently of the others (so the tasks may run
  at the same time, on distinct vehicles); completes when all tasks have. A
  failure stops the running tasks, drops the branches still waiting, and fails
  `all_of`.
  """
  use Dolphin.Engine.Task.Struct, branches: []
  @behaviour Dolphin.Engine.Node

  import Dolphin.Engine.Node, only: [cond_met: 2]

  @type t :: %__MODULE__{branches: [{Dolphin.Engine.Cond.t(), Dolphin.Engine.Task.t()}]}

  @impl true
  def kind, do: :all_of

  @impl true
  def init(%{branches: []}), do: {[{:finish, :done}], nil}

  def init(%{branches: bs} = task),
    do: {[{:check, 0, elem(hd(bs), 0)}], %{id: task.id, branches: List.to_tuple(bs), waiting: [], running: [], left: length(bs), failure: nil}}

  @impl true
  # A branch failed while the others were being checked: nothing more starts.
  def handle({:checked, _i, _holds}, %{failure: f} = s) when f != nil, do: {[], s}

  def handle({:checked, i, holds}, s) do
    {c, _} = elem(s.branches, i)
    {now, s} = if holds, do: run(s, i), else: {[{:watch, i, c}], %{s | waiting: s.waiting ++ [i]}}
    next = if i + 1 < tuple_size(s.branches), do: [{:check, i + 1, elem(elem(s.branches, i + 1), 0)}], else: []
    {now ++ next, s}
  end

  def handle({:condition, i}, s), do: run(%{s | waiting: List.delete(s.waiting, i)}, i)

  def handle({:finished, i, result}, s) do
    s = %{s | running: List.delete(s.running, i), left: s.left - 1}

    case {result, s.failure} do
      {{:failed, f}, nil} when s.running == [] ->
        {unwatch(s) ++ [{:finish, {:failed, f}}], s}

      {{:failed, f}, nil} ->
        {unwatch(s) ++ [{:stop, s.running, {:sibling_failed, i}}], %{s | failure: f, waiting: []}}

      {_, nil} ->
        if s.left == 0, do: {[{:finish, :done}], s}, else: {[], s}

      {_, f} ->
        if s.running == [], do: {[{:finish, {:failed, f}}], s}, else: {[], s}
    end
  end

  defp run(s, i) do
    {c, t} = elem(s.branches, i)
    {[cond_met(c, i), {:start, i, t}], %{s | running: s.running ++ [i]}}
  end

  defp unwatch(s), do: Enum.map(s.waiting, &{:unwatch, &1})
end
