defmodule Dolphin.Engine.On do
  @moduledoc """
  `on(t, set)`: the platform tasks of `t` may only use vehicles of `set`.
  An allocation constraint only: at run time `t` runs in its place, so `on`
  itself starts no process and emits no event.
  """
  use Dolphin.Engine.Task.Struct, task: nil, vehicles: nil

  @type t :: %__MODULE__{task: Dolphin.Engine.Task.t(), vehicles: Dolphin.Fleet.VehicleSet.t()}

  @doc false
  def kind, do: :on
end
