defmodule Dolphin.Engine.During do
  @moduledoc """
  `during(d, t)`: runs `t` for at most `d` milliseconds of clock time, then
  stops it; completes either way. A failure of `t` fails `during`.
  """
  use Dolphin.Engine.Task.Struct, duration: 0, task: nil
  @behaviour Dolphin.Engine.Node

  import Dolphin.Engine.Node, only: [completed: 1]

  @type t :: %__MODULE__{duration: non_neg_integer(), task: Dolphin.Engine.Task.t()}

  @impl true
  def kind, do: :during
  @impl true
  def init(task), do: {[{:timer, :d, task.duration}, {:start, :t, task.task}], %{id: task.id, expired: false}}

  @impl true
  def handle({:timeout, :d}, s), do: {[{:stop, [:t], {:time_limit, s.id}}], %{s | expired: true}}
  def handle({:finished, :t, result}, %{expired: true} = s), do: {[{:finish, completed(result)}], s}
  def handle({:finished, :t, result}, s), do: {[{:cancel_timer, :d}, {:finish, completed(result)}], s}
end
