defmodule Dolphin.Examples.BackendsRelaysTest do
  # The two relays (Listing 4 and the continuous one) run as a user runs
  # them on the simulator and on ArduCopter SITL, compared as the other
  # examples are (test/examples/backends_test.exs). Apart from those so that
  # `make test` can run them in a BEAM of their own beside the others.
  #
  # They fly 4 and 6 SITL instances at 10x, beside the other examples' SITL
  # instances: the simulator's run comes after SITL's, not beside it.
  use Dolphin.Test.BackendsCase,
    beside: false,
    cases: [
      {"relay", 4, "14m", 10, %{"Survey Area 1" => 1, "Survey Area 2" => 1, "Return to base" => 2}},
      {"relay_continuous", 6, "13m", 10, %{"Watch North" => 2, "Watch South" => 2, "Return to base" => 3}}
    ]
end
