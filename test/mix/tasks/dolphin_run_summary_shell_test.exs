defmodule Mix.Tasks.Dolphin.RunSummaryShellTest do
  # The summary of `mix dolphin.run` as a shell shows it, the run in a fresh
  # VM (Dolphin.Test.Shell): one clock for its events and its summary.
  use ExUnit.Case, async: true

  alias Dolphin.Console.Format
  alias Dolphin.Test.Shell

  @moduletag :tmp_dir
  @moduletag timeout: 600_000

  test "--for: the summary's time is the last event's, and says when the script started", %{tmp_dir: dir} do
    script = Path.join(dir, "wait.exs")
    File.write!(script, "use Dolphin.Script\npick(timeout: seconds(60))\nforever do\n  pause(seconds(1))\nend\n")
    events = Path.join(dir, "events.jsonl")

    result = Shell.run("mix dolphin.run #{Shell.quote(script)} --sim 1 --speedup 20 --for 10s --no-tlog --no-check --events #{Shell.quote(events)}")
    assert result.statuses == [0], result.err

    at = fn name -> events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(&:jiffy.decode(&1, [:return_maps])) |> Enum.find(&(&1["event"] == name)) |> Map.fetch!("t_ms") end
    {started, finished} = {at.("script_started"), at.("script_finished")}
    assert started > 0, "the simulated vehicle boots before the script starts"
    assert result.out =~ "[#{String.pad_leading(Format.seconds(at.("released")), 9)}] released [1]"
    assert result.out =~ "script stopped after #{Format.seconds(finished)} of clock time (--for 10s is over, counted from the script's start at #{Format.seconds(started)})"
  end
end
