defmodule Dolphin.Test.SupportHelpersTest do
  # The tests' own helpers whose arithmetic decides what a test demands.
  use ExUnit.Case, async: true

  doctest Dolphin.Test.ExampleRun, only: [least_at_pace: 2]
end
