defmodule Dolphin.Sim.Error do
  @moduledoc """
  Why the simulator could not do what it was asked: `reason` is
  `:bad_option` (an option of `Dolphin.Sim.start/1`, `set_faults/2` or
  `Dolphin.Sim.Local.start/2` that is wrong: the message says which and
  what it takes) or `:start_failed` (the simulated vehicles, or the local
  link they talk to, could not be started).

      iex> Exception.message(%Dolphin.Sim.Error{reason: :bad_option, message: "bad :count 0: at least 1 vehicle"})
      "bad :count 0: at least 1 vehicle"
  """

  defexception [:reason, :message]

  @type t :: %__MODULE__{reason: :bad_option | :start_failed, message: String.t()}

  @doc false
  @spec bad_option(String.t()) :: {:error, t()}
  def bad_option(message), do: {:error, %__MODULE__{reason: :bad_option, message: message}}
end
