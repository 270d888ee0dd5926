defmodule Dolphin.Engine.Idle do
  @moduledoc "`idle(d)`: completes after `d` milliseconds of clock time (`Dolphin.Clock`)."
  use Dolphin.Engine.Task.Struct, duration: 0
  @behaviour Dolphin.Engine.Node

  @type t :: %__MODULE__{duration: non_neg_integer()}

  @impl true
  def kind, do: :idle
  @impl true
  def init(%{duration: d}), do: {[{:timer, :idle, d}], nil}
  @impl true
  def handle({:timeout, :idle}, s), do: {[{:finish, :done}], s}
end
