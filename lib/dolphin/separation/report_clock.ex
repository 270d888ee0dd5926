defmodule Dolphin.Separation.ReportClock do
  @moduledoc """
  When a vehicle's position report was made, in clock time: what the
  separation monitor (`Dolphin.Separation`) moves a view on from.

  A view reaches the monitor some time after the autopilot made it: the
  radio, the link's and the vehicle's processes, the monitor's own queue.
  On a host that falls behind that time grows, and a view moved on only
  from when it *arrived* puts a vehicle where it was, not where it is (at
  10 m/s, a view half a second late is 5 m short).

  Each position report carries the autopilot's own clock (GLOBAL_POSITION_INT's
  `time_boot_ms`, a view's `boot_ms`). The difference between our clock on
  arrival and that clock is the clocks' offset plus the report's delay; its
  least value over the last few seconds is the offset plus the least delay.
  A report was then made at its `boot_ms` plus that least difference: its
  own extra delay is taken out.

      iex> alias Dolphin.Separation.ReportClock
      iex> c = ReportClock.observe(nil, 1_000, 50_020)
      iex> c = ReportClock.observe(c, 1_200, 50_220)
      iex> # this report comes 300 ms later than the others did
      iex> c = ReportClock.observe(c, 1_400, 50_720)
      iex> ReportClock.reported_at(c, 1_400, 50_720)
      50420

  The estimate is never later than the arrival (a report cannot be made
  after it came), and a view without the autopilot's clock is taken as made
  when it came.

  The least difference is kept over the last 2 to 4 s of clock time (two
  buckets of 2 s; after a silence of more than 4 s, the current bucket
  only): an autopilot whose clock runs slower than ours (a SITL behind its
  speed-up on a busy host) raises the difference steadily, and an offset
  kept for ever would then make every report look older than it is. When
  the least difference of a finished bucket is above the one before it
  (a slower clock, or reports held back for more than a bucket), the
  current bucket alone is the base: a report is then placed at most
  (1 − pace) × 2 s too early. A clock that goes back by more than 10 s, or
  a report more than 10 s later than the least (the autopilot rebooted,
  or another one took its id), starts the estimate afresh; one a little
  back (a report overtaken by a later one, over another link) only counts
  for the least difference.
  """

  # The window's bucket, clock ms.
  @bucket_ms 2_000
  # A clock this far back (ms), or a report this much later than the
  # least, is an autopilot that rebooted.
  @reboot_ms 10_000
  # A finished bucket's least difference this much (ms) above the one
  # before it is a rise, not jitter.
  @rise_ms 20

  defstruct [:boot_ms, :least, :since, :before, rising: false]

  @typedoc "One vehicle's estimate (`nil` before its first report)."
  @type t :: %__MODULE__{boot_ms: integer(), least: integer(), since: integer(), before: integer() | nil, rising: boolean()} | nil

  @doc """
  The estimate after a report with the autopilot's clock at `boot_ms` arrived
  at `arrived_ms` of clock time (`boot_ms` `nil`: unchanged).
  """
  @spec observe(t(), integer() | nil, integer()) :: t()
  def observe(clock, nil, _arrived_ms), do: clock

  def observe(%__MODULE__{boot_ms: last} = clock, boot_ms, arrived_ms) when boot_ms > last - @reboot_ms and arrived_ms - boot_ms - @reboot_ms < clock.least do
    difference = arrived_ms - boot_ms
    latest = max(last, boot_ms)
    elapsed = arrived_ms - clock.since

    cond do
      elapsed < @bucket_ms ->
        %{clock | boot_ms: latest, least: min(clock.least, difference)}

      elapsed < 2 * @bucket_ms ->
        rising = clock.before != nil and clock.least > clock.before + @rise_ms
        %{clock | boot_ms: latest, least: difference, since: arrived_ms, before: clock.least, rising: rising}

      # (After a silence, the bucket before is too old to go by.)
      true ->
        %{clock | boot_ms: latest, least: difference, since: arrived_ms, before: nil, rising: false}
    end
  end

  def observe(_clock, boot_ms, arrived_ms), do: %__MODULE__{boot_ms: boot_ms, least: arrived_ms - boot_ms, since: arrived_ms}

  @doc """
  The clock time a report with the autopilot's clock at `boot_ms` was made,
  it having arrived at `arrived_ms`.
  """
  @spec reported_at(t(), integer() | nil, integer()) :: integer()
  def reported_at(%__MODULE__{least: least, before: before, rising: rising}, boot_ms, arrived_ms) when is_integer(boot_ms),
    do: min(arrived_ms, boot_ms + if(rising or before == nil, do: least, else: min(least, before)))

  def reported_at(_clock, _boot_ms, arrived_ms), do: arrived_ms
end
