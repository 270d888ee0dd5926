defmodule Dolphin.CLI.StartError do
  @moduledoc """
  A run whose vehicles or outputs could not be started although its command
  line was right: a port in use, a SITL binary that would not start, an
  events file that cannot be written. `option` is the option that asked for
  it (`"--connect udpin:0.0.0.0:14550"`, `"--events"`), or nil; `reason` is
  what went wrong, as text or as an exception. `mix dolphin.run` exits with
  status 1.

      iex> Exception.message(%Dolphin.CLI.StartError{option: "--connect udpin:0.0.0.0:14550", reason: "address in use"})
      "--connect udpin:0.0.0.0:14550: address in use"
      iex> Exception.message(%Dolphin.CLI.StartError{reason: %RuntimeError{message: "no SITL binary"}})
      "no SITL binary"
  """

  defexception [:option, :reason]

  @type t :: %__MODULE__{option: String.t() | nil, reason: String.t() | Exception.t() | term()}

  @impl true
  def message(%__MODULE__{option: nil, reason: reason}), do: text(reason)
  def message(%__MODULE__{option: option, reason: reason}), do: "#{option}: #{text(reason)}"

  defp text(reason) when is_binary(reason), do: reason
  defp text(reason) when is_exception(reason), do: Exception.message(reason)
  defp text(reason), do: inspect(reason)
end
