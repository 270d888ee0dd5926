defmodule Dolphin.CommandLineError do
  @moduledoc """
  What a command-line tool's work (`Mix.Tasks.Dolphin.Plan.main/1`,
  `Mix.Tasks.Dolphin.Console.start/1`, ...) did not do, in the words the tool
  prints: `reason` is `:usage` when the command line is wrong (`usage`, if
  given, follows the message on its own line) or `:failed` when the work
  failed; `cause` is the error behind it when there is one (an
  `Dolphin.Link.EndpointError`, a `Dolphin.SITL.Error`, ...).

      iex> e = %Dolphin.CommandLineError{reason: :usage, message: "no command given", usage: "usage: mix dolphin.plan ..."}
      iex> Exception.message(e)
      "no command given\\nusage: mix dolphin.plan ..."
  """

  defexception [:reason, :message, :usage, :cause]

  @type t :: %__MODULE__{reason: :usage | :failed, message: String.t(), usage: String.t() | nil, cause: Exception.t() | nil}

  @impl true
  def message(%__MODULE__{message: message, usage: nil}), do: message
  def message(%__MODULE__{message: message, usage: usage}), do: message <> "\n" <> usage
end
