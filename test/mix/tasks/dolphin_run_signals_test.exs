defmodule Mix.Tasks.Dolphin.RunSignalsTest do
  # `mix dolphin.run` in its own OS process, interrupted as an operator or a
  # service manager would: SIGINT (Ctrl-C) and SIGTERM. The --connect runs fly
  # a simulator of this VM, in a Dolphin.Instance of the test's own (its
  # vehicles, its clock's speed-up): async.
  use ExUnit.Case, async: true

  import Dolphin.Test.MixCommand, only: [kill: 2, kill_twice: 3, wait_for: 2, wait_exit: 2, open: 1]

  @moduletag :tmp_dir
  @moduletag timeout: 300_000

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  # It circles until stopped: the signal finds it flying however late it
  # comes (on a loaded host the test may read "armed" seconds after it was
  # written; a mission that ended on its own meanwhile is no stop to see).
  @hover """
  use Dolphin.Script
  v = pick(timeout: seconds(60))
  execute %{v => mission "Hover" do
    take_off location(40.444233, -7.375234, 840)
    loiter_pos location(40.444233, -7.375234, 840)
  end}
  """

  # The stop as --for makes it: every task stopped (not failed), then the
  # vehicles released, then the script's end; the summary says why.
  defp assert_stopped_by(events, output, signal, reason) do
    lines = events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(&:jiffy.decode(&1, [:return_maps, null_term: nil]))
    names = Enum.map(lines, & &1["event"])
    finished = for %{"event" => "task_finished"} = e <- lines, do: e

    assert finished != [], "no task finished: #{inspect(names)}"
    for e <- finished, do: assert(%{"result" => "stopped", "reason" => ^reason} = e)
    last_finished = names |> Enum.with_index() |> Enum.filter(&(elem(&1, 0) == "task_finished")) |> List.last() |> elem(1)
    released = Enum.find_index(names, &(&1 == "released"))
    assert released && last_finished < released, "released before a task stopped: #{inspect(names)}"
    # The script's events end with its end; what its vehicles report may
    # follow it (the heartbeat that shows the hold each accepted comes within
    # a second), nothing else.
    {_, [script_end | after_end]} = Enum.split_while(lines, &(&1["event"] != "script_finished"))
    assert %{"result" => "stopped", "reason" => ^reason} = script_end
    assert Enum.all?(after_end, &(&1["event"] in ~w(mode_changed armed disarmed mission_item_reached))), "after the script's end: #{inspect(after_end)}"
    assert output =~ "script stopped after"
    assert output =~ "(#{signal}): running tasks were stopped, vehicles hold"
    refute output =~ "BREAK"
    refute output =~ "** (EXIT"
    lines
  end

  if Code.ensure_loaded?(Dolphin.Sim) do
    for {signal, status, words} <- [{"INT", 130, "interrupted (SIGINT, Ctrl-C)"}, {"TERM", 143, "terminated (SIGTERM)"}] do
      @tag signal: signal, status: status, words: words
      test "SIG#{signal} stops a --sim run as --for does: tasks stopped, vehicles hold, status #{status}", ctx do
        script = Path.join(ctx.tmp_dir, "hover.exs")
        File.write!(script, @hover)
        events = Path.join(ctx.tmp_dir, "events.jsonl")

        port = run_mix(["dolphin.run", script, "--sim", "1", "--speedup", "10", "--no-tlog", "--events", events])
        wait_for(port, ~r/vehicle 1 armed/)
        kill(port, ctx.signal)
        output = wait_exit(port, ctx.status)

        lines = assert_stopped_by(events, output, ctx.words, "stopped: the run was #{ctx.words}")
        # The mission was flying: its stop had to tell the vehicle to hold.
        assert Enum.any?(lines, &match?(%{"event" => "armed", "vehicle" => 1}, &1))
      end

      @tag signal: signal, status: status, words: words
      test "SIG#{signal} stops a --connect run: the vehicle of another process holds, status #{status}", ctx do
        script = Path.join(ctx.tmp_dir, "hover.exs")
        File.write!(script, @hover)
        events = Path.join(ctx.tmp_dir, "events.jsonl")
        udp = Dolphin.Test.GroundStation.free_udp_port()
        sysid = 77

        {:ok, [^sysid]} = Dolphin.Sim.start(gcs: udp, sysids: [sysid], speedup: 10)

        # (The test's instance stops the simulated vehicle, and its clock, with it.)
        port = run_mix(["dolphin.run", script, "--connect", "udpin:127.0.0.1:#{udp}", "--speedup", "10", "--no-tlog", "--events", events])
        wait_for(port, ~r/vehicle #{sysid} armed/)
        kill(port, ctx.signal)
        output = wait_exit(port, ctx.status)

        assert_stopped_by(events, output, ctx.words, "stopped: the run was #{ctx.words}")
        # The simulator's truth: the vehicle was told to hold where it was.
        assert {:ok, %{mode: :brake, armed: true}} = Dolphin.Sim.info(sysid)
      end
    end
  end

  @patrol """
  use Dolphin.Script
  v = pick()
  forever do
    execute %{v => Dolphin.Engine.FakePlatform.task("patrol", duration: :infinity)}
  end
  """

  # A task whose stop takes 14 s of clock time (the stop timeout is 15 s).
  @slow_stop """
  use Dolphin.Script
  v = pick()
  execute %{v => Dolphin.Engine.FakePlatform.task("slow", duration: :infinity, stop_ms: 14_000)}
  """

  defp event_lines(events), do: events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(&:jiffy.decode(&1, [:return_maps]))

  test "a second Ctrl-C, once the log says the stop goes on, exits at once, saying so, the events file written", %{tmp_dir: dir} do
    script = Path.join(dir, "slow_stop.exs")
    File.write!(script, @slow_stop)
    events = Path.join(dir, "events.jsonl")
    port = run_mix(["dolphin.run", script, "--fake", "1", "--events", events])
    wait_for(port, ~r/task \d+ test "slow" started/)
    kill(port, "INT")
    wait_for(port, ~r/interrupted \(SIGINT, Ctrl-C\): stopping the script/)
    # Said once a repeat of the first signal is no longer taken for one.
    wait_for(port, ~r/still stopping: Ctrl-C or SIGTERM again exits at once/)
    kill(port, "INT")
    output = wait_exit(port, 130)

    assert output =~ "interrupted (SIGINT, Ctrl-C) again: exiting at once, without waiting for the stops"
    # It did not wait for the stop: no task finished, no summary; what the
    # events file had been sent is in it, every line whole.
    names = Enum.map(event_lines(events), & &1["event"])
    assert "task_started" in names
    refute "task_finished" in names
    refute "script_finished" in names
    refute output =~ "script stopped after"
  end

  # `kill -TERM $pid; kill -TERM $pid`, or GNU timeout signalling the run and
  # its process group: one request, however many of the signals arrive
  # (two different ones always both do).
  for {first, second, status, words} <- [{"TERM", "TERM", 143, "terminated (SIGTERM)"}, {"INT", "TERM", nil, nil}] do
    @tag first: first, second: second, status: status, words: words
    test "SIG#{first} and SIG#{second} in a row stop the run in order, with its summary and script_finished", ctx do
      script = Path.join(ctx.tmp_dir, "patrol.exs")
      File.write!(script, @patrol)
      events = Path.join(ctx.tmp_dir, "events.jsonl")
      port = run_mix(["dolphin.run", script, "--fake", "1", "--events", events])
      wait_for(port, ~r/test "patrol" started on vehicle 1/)
      kill_twice(port, ctx.first, ctx.second)

      # Which of two different signals comes first is the VM's affair: the run is stopped by that one.
      {status, words} = if ctx.status, do: {ctx.status, ctx.words}, else: first_of(port)
      output = wait_exit(port, status)

      assert_stopped_by(events, output, words, "stopped: the run was #{words}")
      refute output =~ "exiting at once"
    end
  end

  defp first_of(port) do
    wait_for(port, ~r/(interrupted \(SIGINT, Ctrl-C\)|terminated \(SIGTERM\)): stopping the script/)
    if Dolphin.Test.MixCommand.output() =~ "interrupted (SIGINT, Ctrl-C): stopping", do: {130, "interrupted (SIGINT, Ctrl-C)"}, else: {143, "terminated (SIGTERM)"}
  end

  for {signal, status, words} <- [{"INT", 130, "interrupted (SIGINT, Ctrl-C)"}, {"TERM", 143, "terminated (SIGTERM)"}] do
    @tag signal: signal, status: status, words: words
    test "SIG#{signal} while the script is being compiled ends the command with #{status}, saying so", ctx do
      script = Path.join(ctx.tmp_dir, "held.exs")
      File.write!(script, "use Dolphin.Script\nrequire Dolphin.Test.Hold\nDolphin.Test.Hold.here(\"compiling the script\")\n")
      port = run_mix(["dolphin.run", script, "--sim", "1"])
      wait_for(port, ~r/compiling the script/)
      kill(port, ctx.signal)
      output = wait_exit(port, ctx.status)

      assert output =~ "mix dolphin.run: #{ctx.words}: no script was running; exiting"
      refute output =~ "BREAK"
      refute output =~ "** (EXIT"
    end
  end

  if System.find_executable("script") do
    test "Ctrl-C typed on a terminal stops the run, no BREAK menu, status 130", %{tmp_dir: dir} do
      script = Path.join(dir, "patrol.exs")
      File.write!(script, @patrol)

      events = Path.join(dir, "events.jsonl")
      # script(1) gives the run a terminal; what this test writes is typed on it.
      command = "exec mix dolphin.run '#{script}' --fake 1 --events '#{events}'"
      port = open([System.find_executable("script"), "-q", "-e", "-c", command, "/dev/null"])
      wait_for(port, ~r/test "patrol" started on vehicle 1/)
      Port.command(port, <<3>>)
      output = wait_exit(port, 130)

      assert_stopped_by(events, output, "interrupted (SIGINT, Ctrl-C)", "stopped: the run was interrupted (SIGINT, Ctrl-C)")
    end
  end

  defp run_mix(args), do: Dolphin.Test.MixCommand.start(args)
end
