defmodule Dolphin.Engine.Concurrent do
  @moduledoc """
  `t1 ||| t2 ||| ...`: runs the tasks at the same time, each on its own
  vehicles; completes when all have. When one fails the others are stopped
  (their platform tasks hold their vehicles) and the whole fails with that
  first failure.
  """
  use Dolphin.Engine.Task.Struct, tasks: []
  @behaviour Dolphin.Engine.Node

  @type t :: %__MODULE__{tasks: [Dolphin.Engine.Task.t()]}

  @impl true
  def kind, do: :concurrent

  @impl true
  def init(%{tasks: []}), do: {[{:finish, :done}], nil}

  def init(%{tasks: tasks}) do
    starts = tasks |> Enum.with_index() |> Enum.map(fn {t, i} -> {:start, i, t} end)
    {starts, %{running: Enum.to_list(0..(length(tasks) - 1)), failure: nil}}
  end

  @impl true
  def handle({:finished, i, result}, %{running: running, failure: failure} = s) do
    s = %{s | running: List.delete(running, i)}

    case {result, failure, s.running} do
      {{:failed, f}, nil, []} -> {[{:finish, {:failed, f}}], s}
      {{:failed, f}, nil, others} -> {[{:stop, others, {:sibling_failed, i}}], %{s | failure: f}}
      {_, nil, []} -> {[{:finish, :done}], s}
      {_, nil, _} -> {[], s}
      {_, f, []} -> {[{:finish, {:failed, f}}], s}
      {_, _f, _} -> {[], s}
    end
  end
end
