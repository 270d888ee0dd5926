defmodule Dolphin.Test.Hold do
  @moduledoc """
  A script that stops while it is being compiled, for tests that signal a
  `mix` task at a known moment of its start-up (the script compiled, before
  the pre-flight check and the run):

      use Dolphin.Script
      require Dolphin.Test.Hold
      Dolphin.Test.Hold.here("compiling the script")

  When the compiler reaches `here/1`, the marker is printed on standard
  output and the compiler waits for ever.
  """

  @doc "Prints `marker` when expanded (compile time), then never returns."
  defmacro here(marker) do
    IO.puts(marker)
    Process.sleep(:infinity)
  end
end
