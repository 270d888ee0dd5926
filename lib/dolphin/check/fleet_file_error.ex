defmodule Dolphin.Check.FleetFileError do
  @moduledoc """
  A fleet file (`Dolphin.Check.FleetFile`) that cannot be used: which file
  and what is wrong in it.

      iex> Exception.message(%Dolphin.Check.FleetFileError{file: "fleet.json", message: "vehicle #2: \\"id\\" is missing"})
      ~s(fleet file fleet.json: vehicle #2: "id" is missing)
  """
  defexception [:file, :message]

  @type t :: %__MODULE__{file: String.t() | nil, message: String.t()}

  @impl true
  def message(%__MODULE__{file: nil, message: m}), do: "fleet file: #{m}"
  def message(%__MODULE__{file: file, message: m}), do: "fleet file #{file}: #{m}"
end
