defmodule Dolphin.CLI.UsageError do
  @moduledoc """
  A command line that cannot be run as given: an unknown option, a bad value,
  no script or no such file. `mix dolphin.run` prints it with its usage and
  exits with status 2.

      iex> Exception.message(%Dolphin.CLI.UsageError{message: "no script given"})
      "no script given"
  """

  defexception [:message]

  @type t :: %__MODULE__{message: String.t()}
end
