defmodule Mix.Tasks.OutputFilesShellTest do
  # The files runs and reports write and read, met from the shell: each
  # command a fresh VM (Dolphin.Test.Shell). Simulated vehicles run in the
  # child VMs only: async.
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.{Frame, Tlog}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Test.Shell

  @moduletag :tmp_dir
  @moduletag timeout: 600_000

  @hover """
  use Dolphin.Script
  v = pick(timeout: seconds(60))
  execute(wait_for(position(v) != nil))
  pause(seconds(5))
  release(v)
  """

  defp q(path), do: Shell.quote(path)

  test "an output file in a missing directory: its option named, bad usage (2), nothing flies, no stack", %{tmp_dir: dir} do
    script = Path.join(dir, "hover.exs")
    File.write!(script, @hover)
    missing = Path.join(dir, "missing")

    for option <- ["--tlog", "--events", "--report"] do
      file = Path.join(missing, "out")
      result = Shell.run("mix dolphin.run #{q(script)} --sim 1 --speedup 50 #{option} #{q(file)}")
      assert result.statuses == [2]
      assert result.err =~ "mix dolphin.run: #{option} #{file}: cannot create it: no such directory #{missing}\nusage: mix dolphin.run"
      refute result.err =~ "Error"
      refute result.err =~ "lib/"
      assert result.out == ""
    end
  end

  test "mix dolphin.report: nothing readable in the log or the events is an error (1); an unwritable -o is bad usage (2)", %{tmp_dir: dir} do
    noise = Path.join(dir, "noise.bin")
    File.write!(noise, :crypto.strong_rand_bytes(4096))
    log = Path.join(dir, "two.tlog")
    File.write!(log, [run_bytes(0), run_bytes(600_000_000)])

    result = Shell.run("mix dolphin.report #{q(noise)}")
    assert result.statuses == [1]
    assert result.err =~ "no MAVLink frame in the telemetry log: #{noise}: none of its 4096 bytes is a telemetry-log record"

    result = Shell.run("mix dolphin.report #{q(log)} --events #{q(noise)}")
    assert result.statuses == [1]
    assert result.err =~ "no event in the events file: #{noise}: none of its"
    refute File.exists?(Path.join(dir, "two.html"))

    result = Shell.run("mix dolphin.report #{q(log)} -o #{q(Path.join([dir, "missing", "r.html"]))}")
    assert result.statuses == [2]
    assert result.err =~ "-o #{dir}/missing/r.html: cannot create it: no such directory #{dir}/missing"
  end

  test "mix dolphin.report on a log of two runs reports the last and says so", %{tmp_dir: dir} do
    log = Path.join(dir, "two.tlog")
    File.write!(log, [run_bytes(0), run_bytes(600_000_000)])
    result = Shell.run("mix dolphin.report #{q(log)}")
    assert result.statuses == [0]
    assert result.out =~ "report: #{Path.join(dir, "two.html")}"
    # The last run's 60 s (of the log's 484 frames), not 11 minutes of two flights.
    assert result.out =~ "1 vehicle(s), 484 frames, 60 s of clock time"
    assert result.out =~ "the telemetry log holds 2 runs"
    assert result.out =~ "this report is of run 2, the last, alone (--run N for another)"

    # The page on standard output, the line on standard error.
    result = Shell.run("mix dolphin.report #{q(log)} --run 1 -o - | head -c 15")
    assert result.out == "<!DOCTYPE html>"
    assert result.statuses in [[0, 0], [141, 0]]
    assert result.err == "" or result.err =~ "report: standard output"
  end

  test "the same command twice: the second run replaces the log and says so, and its report is its own", %{tmp_dir: dir} do
    script = Path.join(dir, "hover.exs")
    File.write!(script, @hover)
    tlog = Path.join(dir, "run.tlog")
    events = Path.join(dir, "run.jsonl")
    report = Path.join(dir, "run.html")
    command = "mix dolphin.run #{q(script)} --sim 1 --speedup 50 --tlog #{q(tlog)} --events #{q(events)} --report #{q(report)}"

    first = Shell.run(command)
    assert first.statuses == [0], first.err
    assert first.out =~ "telemetry log: #{tlog}\n"
    second = Shell.run(command)
    assert second.statuses == [0], second.err
    assert second.out =~ "telemetry log: #{tlog} (replaces the file that was there)"
    assert second.out =~ "flight report: #{report} (1 vehicle(s)"
    refute second.err =~ "no flight report"

    result = Shell.run("mix dolphin.report #{q(tlog)} --events #{q(events)} -o #{q(report)}")
    assert result.statuses == [0], result.err
    refute result.out =~ "runs"
  end

  # One simulated run as a log records it, `shift_us` later: a vehicle
  # heard at 2 Hz for 60 s (a heartbeat and a position each time), its
  # boot clock from 0.
  defp run_bytes(shift_us) do
    for half <- 0..120 do
      ts = 1_800_000_000_000_000 + shift_us + half * 500_000
      heartbeat = Frame.encode(%M.Heartbeat{type: 2, autopilot: 3, base_mode: 0x11, mavlink_version: 3}, sysid: 1, compid: 1, seq: rem(2 * half, 256))
      position = Frame.encode(%M.GlobalPositionInt{time_boot_ms: half * 500, lat: 404_442_330 + half * 10, lon: -73_752_340}, sysid: 1, compid: 1, seq: rem(2 * half + 1, 256))
      [Tlog.record(ts, heartbeat), Tlog.record(ts + 1, position)]
    end
  end
end
