defmodule Mix.Tasks.Dolphin.RunSignalsTest do
  # `mix dolphin.run` in its own OS process, interrupted as an operator or a
  # service manager would: SIGINT (Ctrl-C) and SIGTERM. The --connect runs fly
  # a simulator of this VM: it changes the clock's speed-up, so not async.
  use ExUnit.Case, async: false

  @moduletag :tmp_dir
  @moduletag timeout: 300_000

  # Real ms any one step of a child run may take on a loaded machine (a VM
  # boot, a vehicle arming at speed-up 10): generous, never a measurement.
  @step 120_000

  @hover """
  use Dolphin.Script
  v = pick(timeout: seconds(60))
  forever do
    execute %{v => mission "Hover" do
      take_off location(40.444233, -7.375234, 840)
      move 40, 0, 0
      move -40, 0, 0
    end}
  end
  """

  # The stop as --for makes it: every task stopped (not failed), then the
  # vehicles released, the script's end last; the summary says why.
  defp assert_stopped_by(events, output, signal, reason) do
    lines = events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(&:jiffy.decode(&1, [:return_maps, null_term: nil]))
    names = Enum.map(lines, & &1["event"])
    finished = for %{"event" => "task_finished"} = e <- lines, do: e

    assert finished != [], "no task finished: #{inspect(names)}"
    for e <- finished, do: assert(%{"result" => "stopped", "reason" => ^reason} = e)
    last_finished = names |> Enum.with_index() |> Enum.filter(&(elem(&1, 0) == "task_finished")) |> List.last() |> elem(1)
    released = Enum.find_index(names, &(&1 == "released"))
    assert released && last_finished < released, "released before a task stopped: #{inspect(names)}"
    assert %{"event" => "script_finished", "result" => "stopped", "reason" => ^reason} = List.last(lines)
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
        previous = Dolphin.Clock.speedup()
        udp = Dolphin.Test.GroundStation.free_udp_port()
        sysid = 77

        {:ok, [^sysid]} = Dolphin.Sim.start(gcs: udp, sysids: [sysid], speedup: 10)

        on_exit(fn ->
          Dolphin.Sim.stop(sysid)
          Dolphin.Clock.set_speedup(previous)
        end)

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

  test "a second Ctrl-C exits at once, without waiting for the stop", %{tmp_dir: dir} do
    script = Path.join(dir, "slow_stop.exs")

    # A task whose stop takes 14 s of clock time (the stop timeout is 15 s).
    File.write!(script, """
    use Dolphin.Script
    v = pick()
    execute %{v => Dolphin.Engine.TestPlatform.task("slow", duration: :infinity, stop_ms: 14_000)}
    """)

    events = Path.join(dir, "events.jsonl")
    port = run_mix(["dolphin.run", script, "--fake", "1", "--events", events])
    wait_for(port, ~r/task \d+ test "slow" started/)
    kill(port, "INT")
    wait_for(port, ~r/interrupted \(SIGINT, Ctrl-C\): stopping the script .* again to exit at once/)
    kill(port, "INT")
    output = wait_exit(port, 130)

    # It did not wait for the stop: no task finished, no summary.
    names = events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(&(:jiffy.decode(&1, [:return_maps])["event"]))
    refute "task_finished" in names
    refute "script_finished" in names
    refute output =~ "script stopped after"
  end

  if System.find_executable("script") do
    test "Ctrl-C typed on a terminal stops the run, no BREAK menu, status 130", %{tmp_dir: dir} do
      script = Path.join(dir, "patrol.exs")

      File.write!(script, """
      use Dolphin.Script
      v = pick()
      forever do
        execute %{v => Dolphin.Engine.TestPlatform.task("patrol", duration: :infinity)}
      end
      """)

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


  defp run_mix(args), do: open([System.find_executable("mix") | args])

  # The command runs in its own OS process (`mix` execs the VM: the process
  # id is the VM's); whatever is left of it when the test ends is killed.
  defp open([exe | args]) do
    env = [{~c"MIX_ENV", ~c"test"}, {~c"LANG", ~c"C.UTF-8"}, {~c"LC_ALL", ~c"C.UTF-8"}, {~c"TERM", ~c"xterm"}]
    port = Port.open({:spawn_executable, exe}, [:binary, :exit_status, :stderr_to_stdout, args: args, cd: File.cwd!(), env: env])
    {:os_pid, os_pid} = Port.info(port, :os_pid)
    Process.put(:output, "")

    on_exit(fn ->
      for pid <- descendants(os_pid) ++ [os_pid], do: System.cmd("kill", ["-9", Integer.to_string(pid)], stderr_to_stdout: true)
    end)

    port
  end

  defp kill(port, signal) do
    {:os_pid, os_pid} = Port.info(port, :os_pid)
    {_, 0} = System.cmd("kill", ["-#{signal}", Integer.to_string(os_pid)])
  end

  defp descendants(pid) do
    case System.cmd("ps", ["-o", "pid=", "--ppid", Integer.to_string(pid)], stderr_to_stdout: true) do
      {out, 0} -> out |> String.split() |> Enum.map(&String.to_integer/1) |> Enum.flat_map(&(descendants(&1) ++ [&1]))
      _ -> []
    end
  end

  # Waits (bounded) until the output matches.
  defp wait_for(port, pattern) do
    unless Process.get(:output) =~ pattern do
      receive do
        {^port, {:data, data}} ->
          Process.put(:output, Process.get(:output) <> clean(data))
          wait_for(port, pattern)

        {^port, {:exit_status, status}} ->
          flunk("the run ended (status #{status}) before #{inspect(pattern)}:\n#{Process.get(:output)}")
      after
        @step -> flunk("no #{inspect(pattern)} within #{@step} ms:\n#{Process.get(:output)}")
      end
    end
  end

  defp wait_exit(port, expected) do
    receive do
      {^port, {:data, data}} ->
        Process.put(:output, Process.get(:output) <> clean(data))
        wait_exit(port, expected)

      {^port, {:exit_status, status}} ->
        output = Process.get(:output)
        assert status == expected, "exit status #{status}, expected #{expected}:\n#{output}"
        output
    after
      @step -> flunk("the run did not end within #{@step} ms:\n#{Process.get(:output)}")
    end
  end

  # Without terminal escapes and carriage returns.
  defp clean(data), do: data |> String.replace(~r/\e\[[0-9;?]*[A-Za-z]/, "") |> String.replace("\r", "")
end
