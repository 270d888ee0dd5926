defmodule Dolphin.Script.Halt do
  @moduledoc "Raised by `Dolphin.Script.Statements.halt/1` (the word `halt`) to stop the script."
  defexception message: "halted"
end
