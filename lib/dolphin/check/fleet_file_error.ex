defmodule Dolphin.Check.FleetFileError do
  @moduledoc """
  A fleet file (`Dolphin.Check.FleetFile`) that cannot be used: which file
  and every problem found in it (`problems`, one line each; `message` is
  them all).

      iex> Exception.message(Dolphin.Check.FleetFileError.new([~s(vehicle #2: "id" is missing)], "fleet.json"))
      ~s(fleet file fleet.json: vehicle #2: "id" is missing)
      iex> Exception.message(Dolphin.Check.FleetFileError.new([~s(vehicle #1: "battery" must be a number from 0.0 to 1.0, got 2), ~s(vehicle #2: "id" is missing)], "fleet.json"))
      ~s(fleet file fleet.json: 2 problems:\\n  vehicle #1: "battery" must be a number from 0.0 to 1.0, got 2\\n  vehicle #2: "id" is missing)
  """
  defexception [:file, :message, problems: []]

  @type t :: %__MODULE__{file: String.t() | nil, message: String.t(), problems: [String.t()]}

  @doc "The error of `problems` (at least one) in `file` (nil: not read from a file)."
  @spec new([String.t(), ...], String.t() | nil) :: t()
  def new([_ | _] = problems, file \\ nil) do
    message = if match?([_], problems), do: hd(problems), else: "#{length(problems)} problems:\n" <> Enum.map_join(problems, "\n", &("  " <> &1))
    %__MODULE__{file: file, message: message, problems: problems}
  end

  @impl true
  def message(%__MODULE__{file: nil, message: m}), do: "fleet file: #{m}"
  def message(%__MODULE__{file: file, message: m}), do: "fleet file #{file}: #{m}"
end
