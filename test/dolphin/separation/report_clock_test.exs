defmodule Dolphin.Separation.ReportClockTest do
  # When a position report was made, from the autopilot's clock and when
  # reports came: late ones, an autopilot clock that runs slow, a reboot.
  use ExUnit.Case, async: true

  alias Dolphin.Separation.ReportClock

  doctest ReportClock

  # Reports every 200 ms of the autopilot's clock from `boot_ms`, made at
  # `made` (our clock) and each coming `delay.(i)` ms later; the clock after them.
  defp reports(clock, boot_ms, made, n, pace \\ 1.0, delay \\ fn _ -> 0 end) do
    Enum.reduce(0..(n - 1), clock, fn i, clock -> ReportClock.observe(clock, boot_ms + round(200 * i * pace), made + 200 * i + delay.(i)) end)
  end

  # One more report, with the autopilot's clock at `boot_ms`, coming at
  # `arrived_ms`: when it is taken as made.
  defp made_at(clock, boot_ms, arrived_ms), do: clock |> ReportClock.observe(boot_ms, arrived_ms) |> ReportClock.reported_at(boot_ms, arrived_ms)

  test "a report held up is taken as made when the autopilot made it; one on time, when it came" do
    clock = reports(nil, 5_000, 100_000, 10)
    # The 11th, made at 102,000, came 1.5 s late.
    assert made_at(clock, 7_000, 103_500) == 102_000
    assert made_at(clock, 7_000, 102_000) == 102_000
  end

  test "the least delay is the base: reports that all come late by varying amounts are placed by the earliest" do
    clock = reports(nil, 0, 50_000, 10, 1.0, fn i -> 300 + rem(i * 37, 120) end)
    # The quickest of them came 300 ms after it was made: a report that comes 900 ms late is 600 ms older than it looks.
    assert made_at(clock, 2_000, 52_900) == 52_300
  end

  test "never later than it came, and a view with no autopilot clock is taken as made when it came" do
    clock = reports(nil, 0, 10_000, 5)
    # (A report whose clock runs ahead of ours: made, by our clock, when it came.)
    assert ReportClock.reported_at(clock, 5_000, 12_000) == 12_000
    assert ReportClock.observe(clock, nil, 12_000) == clock
    assert ReportClock.reported_at(clock, nil, 12_000) == 12_000
    assert ReportClock.reported_at(nil, 800, 12_000) == 12_000
  end

  test "an autopilot clock that runs at half our pace: once that shows, reports on time are placed within 1 s of when they came" do
    # 10 minutes of reports at half pace, on time: its clock falls 5 min
    # behind ours; every report after the first 6 s is looked at.
    {_clock, worst} =
      Enum.reduce(0..2_999, {nil, 0}, fn i, {clock, worst} ->
        {boot, made} = {round(100 * i), 200 * i}
        clock = ReportClock.observe(clock, boot, made)
        {clock, if(made >= 6_000, do: max(worst, made - ReportClock.reported_at(clock, boot, made)), else: worst)}
      end)

    assert worst <= 1_000
  end

  test "after a silence the bucket before it is not gone by; a report far later than the least starts afresh" do
    clock = reports(nil, 0, 10_000, 10, 0.95)
    # 60 s of nothing, then a report on time (the clock at 0.95 of ours): made when it came.
    assert made_at(clock, 58_900, 71_000) == 71_000
    # A report 30 s later than the least, its clock still going forward (another autopilot with that id).
    assert made_at(clock, 2_000, 42_000) == 42_000
  end

  test "a clock that goes back 10 s or more is an autopilot rebooted: its reports are placed afresh; a little back, one overtaken" do
    clock = reports(nil, 600_000, 1_000_000, 10)
    # Rebooted at 1,003,000: its clock starts at 0 and the first report comes 400 ms late; the next on time.
    rebooted = clock |> ReportClock.observe(0, 1_003_400) |> ReportClock.observe(200, 1_003_200 + 200)
    assert ReportClock.reported_at(rebooted, 200, 1_003_400) == 1_003_400
    # Made at 1,001,000 and overtaken, it comes at 1,003,000; the next, made at 1,002,000, comes late too.
    overtaken = clock |> ReportClock.observe(601_000, 1_003_000) |> ReportClock.observe(602_000, 1_003_500)
    assert ReportClock.reported_at(overtaken, 602_000, 1_003_500) == 1_002_000
  end
end
