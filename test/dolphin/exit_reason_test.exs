defmodule Dolphin.ExitReasonTest do
  use ExUnit.Case, async: true
  doctest Dolphin.ExitReason

  test "an exception carried by a shutdown is worded by its message" do
    assert Dolphin.ExitReason.words({:shutdown, %RuntimeError{message: "boom"}}) == "was shut down (boom)"
  end
end
