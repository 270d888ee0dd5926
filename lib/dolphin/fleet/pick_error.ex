defmodule Dolphin.Fleet.PickError do
  @moduledoc "A `pick` that could not be served in time; `requirement` says what was asked."
  defexception [:requirement, :message]

  @type t :: %__MODULE__{requirement: String.t(), message: String.t()}
end
