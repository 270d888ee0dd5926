defmodule Dolphin.ScriptTest do
  use Dolphin.EngineCase, async: false

  require Dolphin.DSL

  alias Dolphin.Engine.{Cond, Until, WaitFor}
  alias Dolphin.Script
  alias Dolphin.Script.Error

  defp compile!(source) do
    {:ok, script} = Script.compile_string(source, "test_script.exs")
    on_exit(fn -> Script.purge(script) end)
    script
  end

  defp run_source(source, opts \\ []), do: source |> compile!() |> Script.run(opts)

  # A script on one fake vehicle whose task patrols until stopped, started
  # and patrolling: the script and its runner.
  defp start_patrol(ctx) do
    fake_vehicles(ctx, 1)
    me = :erlang.pid_to_list(self())

    script =
      compile!("""
      use Dolphin.Script
      _v = pick()
      execute Dolphin.Engine.FakePlatform.task("patrol", duration: :infinity, notify: :erlang.list_to_pid(#{inspect(me)}))
      """)

    {:ok, pid} = Script.start(script)
    assert_platform(:started, "patrol")
    {script, pid}
  end

  describe "compiling" do
    test "a syntax error is reported with its line" do
      assert {:error, %Error{kind: :syntax, line: 2} = e} = Script.compile_string("use Dolphin.Script\nx = 1 +* 2\n", "bad.exs")
      assert Error.format(e) == "bad.exs:2:8: syntax error before: '*'"
      assert {:error, %Error{kind: :syntax, message: m}} = Script.compile_string("use Dolphin.Script\ny = (2 +\n", "bad.exs")
      assert m =~ "missing terminator: ) (for \"(\" starting at line 2)"
    end

    test "an unknown word is reported with its line, before anything runs" do
      source = """
      use Dolphin.Script
      message("this must not be sent")
      pik(type: :uav)
      """

      assert {:error, %Error{kind: :compile, line: 3, message: m}} = Script.compile_string(source, "typo.exs")
      assert m =~ "undefined function pik/1"
      refute_received {:dolphin, :events, %{event: :message}}
    end

    test "a script without use Dolphin.Script gets a hint" do
      assert {:error, %Error{message: m}} = Script.compile_string("_v = pick(type: :uav)\n", "bare.exs")
      assert m =~ "use Dolphin.Script"
    end

    test "an unbound variable is a compile error with its line" do
      ExUnit.CaptureIO.capture_io(:stderr, fn ->
        assert {:error, %Error{kind: :compile, line: 2}} = Script.compile_string("use Dolphin.Script\nexecute(survey)\n", "x.exs")
      end)
    end
  end

  describe "the macros only build data" do
    test "conditions become closures with their source" do
      v = 7
      assert %Until{cond: %Cond{source: "Dolphin.DSL.battery(v) < 0.3", meta: %{line: _}}} = Dolphin.DSL.until(Dolphin.Engine.idle(1), Dolphin.DSL.battery(v) < 0.3)
      assert %WaitFor{then: %Dolphin.Engine.Idle{}} = Dolphin.DSL.wait_for(true, then: Dolphin.Engine.idle(1))

      one_of =
        Dolphin.DSL.one_of do
          1 > 2 -> Dolphin.Engine.idle(1)
          true -> Dolphin.Engine.idle(2)
        end

      assert %Dolphin.Engine.OneOf{branches: [{%Cond{source: "1 > 2"}, _}, {%Cond{source: "true"}, _}]} = one_of
    end

    test ">>> binds tighter than |||" do
      import Dolphin.DSL, only: [>>>: 2, |||: 2]
      assert %Dolphin.Engine.Concurrent{tasks: [%Dolphin.Engine.Sequence{}, %Dolphin.Engine.Idle{duration: 3}]} = idle(1) >>> idle(2) ||| idle(3)
    end
  end

  describe "running" do
    test "the vocabulary end to end: pick, execute, conditions on signals, all_of, one_of, loops", ctx do
      [_a, _b] = fake_vehicles(ctx, 2)

      source = """
      use Dolphin.Script
      alias Dolphin.Engine.FakePlatform

      v = pick(type: :uav, timeout: seconds(5))
      survey = FakePlatform.task("survey", duration: :infinity)

      execute until(survey, poll(:enough)) ||| (idle(10) >>> action do post(:enough, true) end)
      message("consumed: \#{consume(:enough, true)}, again: \#{consume(:enough, true)}")

      execute all_of do
        true -> idle(5)
        poll(:go) -> idle(5)
        true -> action do post(:go, 1) end
      end

      execute one_of do
        poll(:go, &(&1 > 5)) -> action do message("wrong branch") end
        poll(:go) -> action do message("right branch") end
      end

      execute wait_for(connected?(v) and battery(v) > 0.5, then: condition(mission_progress(v) == {0, 0}))
      repeat(2) do message("twice") end
      n = forever(0, fn n -> if n == 3, do: throw({:stop, n}), else: n + 1 end)
      message(n)
      """

      assert {:error, %Error{kind: :failed, message: m}} = run_source(source)
      # the loop ends with the throw: everything before it ran
      assert m =~ "throw: {:stop, 3}"
      texts = for {:dolphin, :events, %{event: :message, text: t}} <- collect_messages(), do: t
      assert texts == ["consumed: true, again: false", "right branch", "twice", "twice"]
    end

    test "execute with a map runs each task on its own set; _ takes any picked vehicle", ctx do
      [a, b, c] = fake_vehicles(ctx, 3)

      source = """
      use Dolphin.Script
      alias Dolphin.Engine.FakePlatform
      me = :erlang.list_to_pid(#{inspect(:erlang.pid_to_list(self()))})
      [v1, v2] = for id <- [#{a}, #{b}], do: pick(id: id)
      _other = pick(id: #{c})
      execute %{
        v1 => FakePlatform.task("one", duration: 1, notify: me),
        v2 => FakePlatform.task("two", duration: 1, notify: me),
        _: FakePlatform.task("any", duration: 1, notify: me)
      }
      release([v1, v2])
      """

      assert {:ok, %{result: :done}} = run_source(source)
      assert %{vehicle: ^a} = assert_platform(:started, "one")
      assert %{vehicle: ^b} = assert_platform(:started, "two")
      assert %{vehicle: ^c} = assert_platform(:started, "any")
    end

    test "a failed task stops the script, saying what, where (the line) and why", ctx do
      fake_vehicles(ctx, 1)

      source = """
      use Dolphin.Script
      alias Dolphin.Engine.FakePlatform
      v = pick()
      broken = FakePlatform.task("survey", duration: 1, result: {:fail, "GPS glitch"})

      execute %{v => broken}
      message("not reached")
      """

      assert {:error, %Error{kind: :failed, line: 6, message: m} = e} = run_source(source)
      assert m =~ ~s(execute failed: test "survey")
      assert m =~ "GPS glitch"
      assert Error.format(e) =~ "test_script.exs:6: "
    end

    test "a pick that times out stops the script naming the requirement" do
      assert {:error, %Error{line: 2, message: m}} = run_source("use Dolphin.Script\npick(type: :uuv, timeout: 5)\n")
      assert m =~ "pick timed out after 5 ms: wanted 1 vehicle, type :uuv"
    end

    test "halt, from the script or from a task, stops the script", ctx do
      assert {:error, %Error{kind: :halted, message: "halted: enough", line: 2}} = run_source("use Dolphin.Script\nhalt(\"enough\")\n")

      fake_vehicles(ctx, 1)

      source = """
      use Dolphin.Script
      _v = pick()
      execute Dolphin.Engine.FakePlatform.task("loiter", duration: :infinity) ||| (idle(5) >>> action do halt("from a task") end)
      """

      assert {:error, %Error{kind: :halted, message: "halted: from a task"}} = run_source(source)
    end

    test "execute action do ... end runs the action" do
      assert {:ok, _} = run_source("use Dolphin.Script\nexecute action do\n  message(\"inside\")\nend\n")
      assert_received {:dolphin, :events, %{event: :message, text: "inside"}}
    end

    test "for: stops the script at its time, stopping its tasks", ctx do
      fake_vehicles(ctx, 1)
      me = :erlang.pid_to_list(self())

      source = """
      use Dolphin.Script
      _v = pick()
      forever do
        execute Dolphin.Engine.FakePlatform.task("patrol", duration: :infinity, notify: :erlang.list_to_pid(#{inspect(me)}))
      end
      """

      assert {:ok, %{result: :stopped}} = run_source(source, for: 50)
      assert_platform(:started, "patrol")
      # Stopped for the script's reason, not as the orphan of its killed code.
      assert %{reason: :deadline} = assert_platform(:stopped, "patrol")
    end

    test "stop/2: the tasks stop for the script's reason, then the vehicles are released, then the script ends", ctx do
      fake_vehicles(ctx, 1)
      me = :erlang.pid_to_list(self())

      source = """
      use Dolphin.Script
      _v = pick()
      forever do
        execute Dolphin.Engine.FakePlatform.task("patrol", duration: :infinity, notify: :erlang.list_to_pid(#{inspect(me)}))
      end
      """

      {:ok, pid} = Script.start(compile!(source))
      assert_platform(:started, "patrol")
      Script.stop(pid, {:signal, :sigterm})
      assert {:ok, %{result: :stopped}} = Script.await(pid)
      assert %{reason: {:signal, :sigterm}} = assert_platform(:stopped, "patrol")

      # Everything was emitted before the script's answer, in the order it happened.
      {:messages, messages} = Process.info(self(), :messages)
      events = for {:dolphin, :events, %{event: e} = event} <- messages, e in [:task_finished, :script_finished], do: event

      assert [
               %{event: :task_finished, result: :stopped, reason: "stopped: the run was terminated (SIGTERM)"},
               %{event: :script_finished, result: :stopped, reason: "stopped: the run was terminated (SIGTERM)"}
             ] = events
    end

    test "a running script's runner is an OTP process: :sys.get_state/1 and :sys.trace/2 see into it", ctx do
      {script, pid} = start_patrol(ctx)

      assert %{script: ^script, code: code, ctx: %Dolphin.Engine.Context{script: ^pid}} = :sys.get_state(pid)
      assert Process.alive?(code)
      assert {:status, ^pid, {:module, :gen_server}, _} = :sys.get_status(pid)
      # The debug machinery behind :sys.trace/2 sees the messages it handles.
      :ok = :sys.log(pid, true)
      send(pid, :nothing_it_expects)
      assert {:ok, [_ | _] = log} = :sys.log(pid, :get)
      assert {:in, :nothing_it_expects} in log
      :ok = :sys.log(pid, false)

      Script.stop(pid, :operator)
      assert {:ok, %{result: :stopped}} = Script.await(pid)
      assert %{reason: :operator} = assert_platform(:stopped, "patrol")
    end

    test "a script runs under Dolphin.Script.Supervisor; its shutdown stops the tasks, then the script says it ended", ctx do
      {_script, pid} = start_patrol(ctx)
      assert {:undefined, pid, :worker, [Dolphin.Script.Runner]} in DynamicSupervisor.which_children(Dolphin.Script.Supervisor)

      # As the application's shutdown does it: the supervisor's exit.
      :ok = DynamicSupervisor.terminate_child(Dolphin.Script.Supervisor, pid)
      assert %{reason: :shutdown} = assert_platform(:stopped, "patrol")
      assert {:ok, %{result: :stopped}} = Script.await(pid)
      assert_received {:dolphin, :events, %{event: :script_finished, result: :stopped, reason: "stopped: shutting down"}}
    end

    test "a script whose caller dies stops its tasks, then says it ended", ctx do
      fake_vehicles(ctx, 1)
      me = self()

      script =
        compile!("""
        use Dolphin.Script
        _v = pick()
        execute Dolphin.Engine.FakePlatform.task("patrol", duration: :infinity, notify: :erlang.list_to_pid(#{inspect(:erlang.pid_to_list(me))}))
        """)

      # The caller runs in the test's context (its fleet and clock).
      context = Dolphin.Engine.Context.current()

      caller =
        spawn(fn ->
          Dolphin.Engine.Context.put(context)
          {:ok, pid} = Script.start(script)
          send(me, {:script, pid})
          Process.sleep(:infinity)
        end)

      caller_ref = Process.monitor(caller)
      assert_receive {:script, pid}, 5_000
      ref = Process.monitor(pid)
      # The monitor is a signal to the runner, and signals from one sender
      # are taken in order: once the runner has answered a system message
      # sent after it, the monitor is in place. Signals from two senders
      # keep no order, so without this the caller's exit, sent later, was
      # once taken first on a loaded VM, and the monitor's DOWN came as
      # :noproc after the script's last event.
      _ = :sys.get_state(pid, 30_000)
      # A loaded run once found the script ended before this point (its
      # monitor said :noproc): if it comes again, the failure tells how.
      receive do
        {:DOWN, ^ref, :process, ^pid, why} ->
          flunk("the script ended before its caller was killed (#{inspect(why)}); caller alive: #{Process.alive?(caller)}; received: #{inspect(Process.info(self(), :messages), limit: :infinity)}")
      after
        0 -> :ok
      end

      assert_platform(:started, "patrol")
      Process.exit(caller, :kill)
      assert_receive {:DOWN, ^caller_ref, :process, ^caller, :killed}, 5_000
      assert %{reason: :shutdown} = assert_platform(:stopped, "patrol")
      assert_receive {:DOWN, ^ref, :process, ^pid, :normal}, 30_000
      assert_received {:dolphin, :events, %{event: :script_finished, result: :stopped, reason: "stopped: shutting down"}}
    end

    test "ask, send_message and set_connection_timeout act for the script", ctx do
      [a] = fake_vehicles(ctx, 1)

      source = """
      use Dolphin.Script
      v = pick()
      set_connection_timeout(minutes(10))
      send_message(v, {:hello, ask("Go?")})
      """

      assert {:ok, _} = run_source(source, ask: fn "Go?" -> "yes" end)
      assert FakeSource.messages(ctx.source, a) == [{:hello, "yes"}]
      assert FakeSource.timeout(ctx.source, a) == 600_000
    end

    test "picks are released when the script ends", ctx do
      [a] = fake_vehicles(ctx, 1)
      assert {:ok, _} = run_source("use Dolphin.Script\npick()\n")
      Dolphin.Test.Wait.until(fn -> match?({:ok, _}, Dolphin.Fleet.pick(ctx.fleet, self(), id: a, timeout: 0)) end)
    end
  end

  if Code.ensure_loaded?(Dolphin.DSL.Mission) do
    test "missions are tasks in scripts" do
      source = """
      use Dolphin.Script
      home_pos = location(40.444233, -7.375234, 820)
      simple_mission =
        mission "Survey Area" do
          home home_pos
          take_off location(40.444233, -7.375234, 1200)
          move 100, 200, 100
          move_and_loiter_pos 200, 100, -20, 50
        end
      task = until(simple_mission, false) >>> idle(1)
      %Dolphin.Engine.Sequence{tasks: [%Dolphin.Engine.Until{task: %Dolphin.Engine.PlatformTask{spec: %Dolphin.Mission{name: "Survey Area"}}}, _]} = task
      """

      assert {:ok, _} = run_source(source)
    end
  end

  defp collect_messages(acc \\ []) do
    receive do
      {:dolphin, :events, %{event: :message}} = m -> collect_messages([m | acc])
      {:dolphin, :events, _} -> collect_messages(acc)
    after
      0 -> Enum.reverse(acc)
    end
  end
end
