defmodule Dolphin.Engine.Concurrent do
  @moduledoc """
  `t1 ||| t2 ||| ...`: runs the tasks at the same time, each on its own
  vehicles; completes when all have. When one fails the others are stopped
  (their platform tasks hold their vehicles), those not started yet never
  start, and the whole fails with that first failure.
  """
  use Dolphin.Engine.Task.Struct, tasks: []
  @behaviour Dolphin.Engine.Node

  @type t :: %__MODULE__{tasks: [Dolphin.Engine.Task.t()]}

  @impl true
  def kind, do: :concurrent

  @impl true
  def init(%{tasks: []}), do: {[{:finish, :done}], nil}
  def init(%{tasks: tasks}), do: start_next(%{tasks: List.to_tuple(tasks), next: 0, running: MapSet.new(), failure: nil})

  # One start at a time, so that a failure while starting stops the rest.
  # (`running` is a set: a thousand tasks end in any order.)
  defp start_next(%{next: i} = s),
    do: {[{:start, i, elem(s.tasks, i)}, :continue], %{s | next: i + 1, running: MapSet.put(s.running, i)}}

  @impl true
  def handle(:continue, %{failure: nil, next: next, tasks: tasks} = s) when next < tuple_size(tasks), do: start_next(s)
  def handle(:continue, s), do: {[], s}

  def handle({:finished, i, result}, s) do
    s = %{s | running: MapSet.delete(s.running, i)}
    all_started = s.next == tuple_size(s.tasks)
    none_left = MapSet.size(s.running) == 0

    case {result, s.failure, none_left} do
      {{:failed, f}, nil, true} -> {[{:finish, {:failed, f}}], s}
      {{:failed, f}, nil, false} -> {[{:stop, s.running |> MapSet.to_list() |> Enum.sort(), {:sibling_failed, i}}], %{s | failure: f}}
      {_, nil, true} when all_started -> {[{:finish, :done}], s}
      {_, nil, _} -> {[], s}
      {_, f, true} -> {[{:finish, {:failed, f}}], s}
      {_, _f, _} -> {[], s}
    end
  end
end
