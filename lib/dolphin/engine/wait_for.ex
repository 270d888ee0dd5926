defmodule Dolphin.Engine.WaitFor do
  @moduledoc """
  `wait_for(c, then: t)`: waits until `c` holds, then runs `t` and ends as it
  does; `wait_for(c)` alone completes when `c` holds.
  """
  use Dolphin.Engine.Task.Struct, cond: nil, then: nil
  @behaviour Dolphin.Engine.Node

  import Dolphin.Engine.Node, only: [cond_met: 1, completed: 1]

  @type t :: %__MODULE__{cond: Dolphin.Engine.Cond.t(), then: Dolphin.Engine.Task.t() | nil}

  @impl true
  def kind, do: :wait_for
  @impl true
  def init(task), do: {[{:check, :c, task.cond}], task}

  @impl true
  def handle({:checked, :c, true}, task), do: {[cond_met(task.cond), go(task)], task}
  def handle({:checked, :c, false}, task), do: {[{:watch, :c, task.cond}], task}
  def handle({:condition, :c}, task), do: {[cond_met(task.cond), go(task)], task}
  def handle({:finished, :then, result}, task), do: {[{:finish, completed(result)}], task}

  defp go(%{then: nil}), do: {:finish, :done}
  defp go(%{then: t}), do: {:start, :then, t}
end
