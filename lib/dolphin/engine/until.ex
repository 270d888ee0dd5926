defmodule Dolphin.Engine.Until do
  @moduledoc """
  `until(t, c)`: runs `t` until `c` holds — then `t` is stopped and `until`
  completes — or until `t` completes. If `c` holds when `until` starts, `t`
  does not start. A failure of `t` fails `until`.
  """
  use Dolphin.Engine.Task.Struct, task: nil, cond: nil
  @behaviour Dolphin.Engine.Node

  import Dolphin.Engine.Node, only: [cond_met: 1, completed: 1]

  @type t :: %__MODULE__{task: Dolphin.Engine.Task.t(), cond: Dolphin.Engine.Cond.t()}

  @impl true
  def kind, do: :until
  @impl true
  def init(task), do: {[{:check, :c, task.cond}], %{task: task, met: false}}

  @impl true
  def handle({:checked, :c, true}, s), do: {[cond_met(s.task.cond), {:finish, :done}], s}
  def handle({:checked, :c, false}, s), do: {[{:watch, :c, s.task.cond}, {:start, :t, s.task.task}], s}
  def handle({:condition, :c}, s), do: {[cond_met(s.task.cond), {:stop, [:t], {:condition_met, s.task.id}}], %{s | met: true}}
  def handle({:finished, :t, result}, %{met: true} = s), do: {[{:finish, completed(result)}], s}
  def handle({:finished, :t, result}, s), do: {[{:unwatch, :c}, {:finish, completed(result)}], s}
end
