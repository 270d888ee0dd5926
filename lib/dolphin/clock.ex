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
  call, written only when it changes).
  """

  @key {__MODULE__, :state}

  @typedoc "Milliseconds of clock time."
  @type clock_ms :: non_neg_integer()

  @doc "The speed-up factor (1 = real time)."
  @spec speedup() :: number()
  def speedup, do: elem(state(), 0)

  @doc """
  Sets the speed-up factor, a positive number. Timers already running keep the
  real duration they were given.
  """
  @spec set_speedup(number()) :: :ok
  def set_speedup(k) when is_number(k) and k > 0 do
    now = now_ms()
    :persistent_term.put(@key, {k, System.monotonic_time(:microsecond), now})
  end

  def set_speedup(other), do: raise(ArgumentError, "speed-up must be a positive number, got: #{inspect(other)}")

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

  defp state, do: :persistent_term.get(@key, {1, 0, 0})
end
