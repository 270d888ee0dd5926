defmodule Dolphin.Check.Clock do
  @moduledoc false
  # The pre-flight check's time source: its own fast clock (2,000 times
  # real time), independent of `Dolphin.Clock`'s speed-up, so that a dry run
  # of a script's pauses, waits and flights takes a moment and leaves the
  # speed-up of a run that follows untouched.

  @behaviour Dolphin.Engine.TimeSource

  @speedup 2_000

  @doc false
  @spec speedup() :: pos_integer()
  def speedup, do: @speedup

  @impl true
  def now_ms, do: div(System.monotonic_time(:microsecond) * @speedup, 1000)

  @impl true
  def send_after(pid, msg, ms), do: Process.send_after(pid, msg, to_real(ms))

  @impl true
  def cancel(ref) do
    Process.cancel_timer(ref, info: false)
    :ok
  end

  @impl true
  def sleep(ms), do: Process.sleep(to_real(ms))

  # Bounds (not timers) stay generous: the stand-in vehicles answer at once,
  # but the machine may be loaded.
  @impl true
  def real_ms(ms), do: max(to_real(ms), 2_000)

  defp to_real(ms) when ms <= 0, do: 0
  defp to_real(ms), do: max(1, div(ms, @speedup))
end
