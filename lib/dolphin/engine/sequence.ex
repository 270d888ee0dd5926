defmodule Dolphin.Engine.Sequence do
  @moduledoc """
  `t1 >>> t2 >>> ...`: runs the tasks one after the other. A failure fails the
  sequence (the rest does not run); a task stopped from outside (by the
  operator) counts as completed and the sequence goes on.
  """
  use Dolphin.Engine.Task.Struct, tasks: []
  @behaviour Dolphin.Engine.Node

  @type t :: %__MODULE__{tasks: [Dolphin.Engine.Task.t()]}

  @impl true
  def kind, do: :sequence
  @impl true
  def init(%{tasks: []}), do: {[{:finish, :done}], nil}
  def init(%{tasks: [first | rest]}), do: {[{:start, 0, first}], rest}

  @impl true
  def handle({:finished, _i, {:failed, _} = failed}, rest), do: {[{:finish, failed}], rest}
  def handle({:finished, _i, _}, []), do: {[{:finish, :done}], []}
  def handle({:finished, i, _}, [next | rest]), do: {[{:start, i + 1, next}], rest}
end
