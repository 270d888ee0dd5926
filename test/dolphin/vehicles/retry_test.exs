defmodule Dolphin.Vehicles.RetryTest do
  use ExUnit.Case, async: true

  import Dolphin.Property

  alias :proper_types, as: T
  alias Dolphin.Vehicles.Retry

  doctest Retry

  test "more loss, never fewer tries; enough that all fail with a chance under 1e-6 (up to 79 % round-trip loss)" do
    check(
      forall({T.integer(0, 79), T.integer(0, 79)}, fn {a, b} ->
        {lo, hi} = {min(a, b) / 100, max(a, b) / 100}
        assert Retry.attempts(lo) <= Retry.attempts(hi)
        assert :math.pow(hi, Retry.attempts(hi)) <= 1.0e-6 * (1 + 1.0e-9)
        true
      end),
      numtests: 300
    )
  end

  test "the timeout follows the round trip, between the retry floor and the ceiling, whatever the speed-up" do
    check(
      forall({T.list(T.integer(0, 5_000)), T.integer(1, 200)}, fn {samples, k} ->
        t = Retry.timeout(samples, 1_000, k)
        assert t >= Dolphin.Clock.retry_real_ms(0, k) and t <= Dolphin.Clock.retry_real_ms(1_000, k)
        if samples != [] and 2 * Enum.max(samples) + 2 < Dolphin.Clock.retry_real_ms(1_000, k), do: assert(t <= max(2 * Enum.max(samples) + 2, 20))
        true
      end),
      numtests: 300
    )
  end
end
