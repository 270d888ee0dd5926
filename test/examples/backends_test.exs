defmodule Dolphin.Examples.BackendsTest do
  # The examples that fly, run as a user runs them on both kinds of vehicles —
  # `mix dolphin.run examples/NAME.exs --sim N` and `--sitl N` (ArduCopter's
  # own flight code) — with the same `--for`, and compared on a normalised
  # history: for each mission the script flew, in order, how each run of it
  # ended and which of its items were reached; and how the script ended.
  # ArduCopter takes longer than the simulator here and there (its EKF needs
  # ~40 s before arming), so a run bounded by `--for` may get further on one
  # than on the other: the histories are compared as far as both went, and
  # each example names how far that must at least be.
  #
  # The two relays: test/examples/backends_relays_test.exs.
  use Dolphin.Test.BackendsCase,
    cases: [
      {"search_and_signal", 3, nil, 10, %{"Search east" => 1, "Search west" => 1, "Home" => 1}},
      {"two_vehicles", 2, "14m", 15, %{"Survey Area 1" => 1, "Survey Area 2" => 1, "Return to base" => 2}},
      {"single_vehicle", 1, "14m", 15, %{"Survey Area" => 1, "Return to base" => 1}},
      {"standby_patrols", 2, nil, 15, %{"Tower 1" => 2, "Tower 2" => 2, "Home" => 4}},
      {"photo_patrol", 1, nil, 15, %{"Field patrol" => 1, "Home" => 1}}
    ]
end
