defmodule Dolphin.Clock do
  @moduledoc """
  The one time source of Dolphin, with a speed-up factor.

  A simulated fleet can run K times faster than real time; then every timer of
  the ground station must run K times faster too (the vehicles' own timers, a
  GCS failsafe for one, count in their time). So nothing in Dolphin calls
  `Process.send_after/3` or `:timer` with a duration directly: durations are
  *clock* milliseconds, converted here.

      iex> Dolphin.Clock.to_real_ms(1_000, 50)
      20
      iex> Dolphin.Clock.to_real_ms(1, 50)
      1

  `now_ms/0` is monotonic clock time in milliseconds. Changing the speed-up
  (`set_speedup/1`) keeps `now_ms/0` continuous: the clock goes on from where it
  was, at the new rate. The factor is kept in `:persistent_term` (read on every
  call, written only when it changes), one per `Dolphin.Instance`: a clock
  is the calling process's instance's, so two instances in one BEAM (two
  tests) fly at their own speed-ups.

  ## Limits

  The speed-up is a number from 0.01 to 1000. Above 1000 the simulated
  vehicles (`Dolphin.Sim`) cannot keep up with the clock even on an idle
  machine: each steps its model in 50 ms steps, at most 40 of them per
  timer tick, and a timer ticks every millisecond or two at best. Measured
  with one vehicle and nothing else running: in step at 500×, barely at
  1000× (7 s of its time behind after 3,000 s), and at 2,000× or 20,000×
  still at 1000×, ever further behind. A fleet with its ground station
  keeps a lower pace, what the machine's cores sustain (`bench/sim.exs`:
  10 vehicles in step up to 200× on two cores). 0.01, a hundred times
  slower than real time, is the slowest.

  A timer holds at most 4,294,967,295 ms of real time (49.7 days, an
  Erlang timer's limit): at speed-up K, a wait of at most that times K of
  clock time (`max_wait_ms/1`).
  """

  @min_speedup 0.01
  @max_speedup 1000
  @max_timer_ms 4_294_967_295

  @typedoc "Milliseconds of clock time."
  @type clock_ms :: non_neg_integer()

  @doc "The speed-up factor (1 = real time)."
  @spec speedup() :: number()
  def speedup, do: elem(state(), 0)

  @doc """
  Sets the speed-up factor, a number from #{@min_speedup} to #{@max_speedup}
  (see "Limits" above; anything else raises `ArgumentError`). Timers already
  running keep the real duration they were given.
  """
  @spec set_speedup(number()) :: :ok
  def set_speedup(k) do
    if speedup?(k), do: :persistent_term.put(key(), {k, System.monotonic_time(:microsecond), now_ms()}), else: raise(ArgumentError, speedup_rule(k))
  end

  @doc """
  Whether `k` is a speed-up the clock and the simulator hold.

      iex> Dolphin.Clock.speedup?(200)
      true
      iex> Dolphin.Clock.speedup?(1.0e9)
      false
  """
  @spec speedup?(term()) :: boolean()
  def speedup?(k), do: is_number(k) and k >= @min_speedup and k <= @max_speedup

  @doc """
  What a speed-up must be, said of `k`.

      iex> Dolphin.Clock.speedup_rule(0)
      "a speed-up is a number from 0.01 to 1000 (beyond 1000 the simulated vehicles cannot keep up with the clock), got 0"
  """
  @spec speedup_rule(term()) :: String.t()
  def speedup_rule(k),
    do: "a speed-up is a number from #{@min_speedup} to #{@max_speedup} (beyond #{@max_speedup} the simulated vehicles cannot keep up with the clock), got #{inspect(k)}"

  @doc "The fastest speed-up (see \"Limits\")."
  @spec max_speedup() :: pos_integer()
  def max_speedup, do: @max_speedup

  @doc """
  The longest wait, in clock milliseconds, that a timer holds at speed-up `k`
  (see "Limits").

      iex> Dolphin.Clock.max_wait_ms(1)
      4294967295
      iex> Dolphin.Clock.max_wait_ms(10)
      42949672950
  """
  @spec max_wait_ms(number()) :: pos_integer()
  def max_wait_ms(k \\ speedup()), do: trunc(@max_timer_ms * k)

  @doc "Clock time now, in milliseconds (monotonic; its origin is arbitrary)."
  @spec now_ms() :: integer()
  def now_ms do
    {k, real_origin, clock_origin} = state()
    clock_origin + trunc((System.monotonic_time(:microsecond) - real_origin) * k / 1000)
  end

  @doc "The real milliseconds that `clock_ms` take at speed-up `k` (at least 1 for a positive duration)."
  @spec to_real_ms(number(), number()) :: non_neg_integer()
  def to_real_ms(clock_ms, k \\ speedup())
  def to_real_ms(clock_ms, _k) when clock_ms <= 0, do: 0
  def to_real_ms(clock_ms, k), do: max(1, round(clock_ms / k))

  @retry_floor_ms 20

  @doc """
  The real milliseconds to wait for an answer before retrying, for a wait of
  `clock_ms` in clock time: never under #{@retry_floor_ms} ms, because a round
  trip through the network and the host's scheduler does not get faster with
  the speed-up.

      iex> Dolphin.Clock.retry_real_ms(1_500, 1)
      1500
      iex> Dolphin.Clock.retry_real_ms(1_500, 200)
      20
  """
  @spec retry_real_ms(number(), number()) :: pos_integer()
  def retry_real_ms(clock_ms, k \\ speedup()), do: max(to_real_ms(clock_ms, k), @retry_floor_ms)

  @doc "Sends `msg` to `dest` after `clock_ms` of clock time; like `Process.send_after/3`."
  @spec send_after(pid() | atom(), term(), number()) :: reference()
  def send_after(dest, msg, clock_ms), do: Process.send_after(dest, msg, to_real_ms(clock_ms))

  @doc "Sleeps for `clock_ms` of clock time."
  @spec sleep(number()) :: :ok
  def sleep(clock_ms), do: Process.sleep(to_real_ms(clock_ms))

  defp state, do: :persistent_term.get(key(), {1, 0, 0})

  defp key, do: {__MODULE__, Dolphin.Instance.current()}
end
