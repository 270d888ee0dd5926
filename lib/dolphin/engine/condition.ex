defmodule Dolphin.Engine.Condition do
  @moduledoc "`condition(c)`: completes when `c` holds (at once if it already does)."
  use Dolphin.Engine.Task.Struct, cond: nil
  @behaviour Dolphin.Engine.Node

  import Dolphin.Engine.Node, only: [cond_met: 1]

  @type t :: %__MODULE__{cond: Dolphin.Engine.Cond.t()}

  @impl true
  def kind, do: :condition
  @impl true
  def init(%{cond: c}), do: {[{:check, :c, c}], c}
  @impl true
  def handle({:checked, :c, true}, c), do: {[cond_met(c), {:finish, :done}], c}
  def handle({:checked, :c, false}, c), do: {[{:watch, :c, c}], c}
  def handle({:condition, :c}, c), do: {[cond_met(c), {:finish, :done}], c}
end
