defmodule Mix.Tasks.Dolphin.ConsoleTest do
  # Starts links and simulated vehicles in the application, and an IEx
  # session in another BEAM: not async.
  use ExUnit.Case, async: false

  alias Mix.Tasks.Dolphin.Console, as: Task

  @moduletag :tmp_dir

  describe "options" do
    test "parsed strictly, with errors that say what is wrong" do
      assert Task.parse(["--sim", "2", "--speedup", "20"]) == {:ok, [sim: 2, speedup: 20.0]}

      assert Task.parse(["--connect", "udpin:0.0.0.0:14550", "--connect", "tcp:127.0.0.1:5760"]) ==
               {:ok, [connect: "udpin:0.0.0.0:14550", connect: "tcp:127.0.0.1:5760"]}

      assert "bad option --bogus" = message(Task.parse(["--bogus"]))
      assert "--sim 0: a number of vehicles from 1 to 16256 (254 a network, each with a system id of its own there)" = message(Task.parse(["--sim", "0"]))
      assert "--speedup -1: a number from 0.01 to 1000" <> _ = message(Task.parse(["--speedup", "-1"]))
      assert "--sitl 255: a number of vehicles from 1 to 254" <> _ = message(Task.parse(["--sitl", "255"]))
      assert "--forward udpin:0.0.0.0:14551: udpout:HOST:PORT here, not udpin" = message(Task.parse(["--forward", "udpin:0.0.0.0:14551"]))
      assert "--connect udpin:0.0.0.0:99999: the port 99999 is not within 1..65535" = message(Task.parse(["--connect", "udpin:0.0.0.0:99999"]))
      assert "unexpected argument \"x.exs\"" <> _ = message(Task.parse(["x.exs"]))
      assert "--tlog /no/such/dir/c.tlog: cannot create it: no such directory /no/such/dir" = message(Task.parse(["--tlog", "/no/such/dir/c.tlog"]))
    end

    test "without IEx it starts nothing and says to use iex -S" do
      assert_raise Mix.Error, ~r/run it as `iex -S mix dolphin.console --sim 1`/, fn -> Task.run(["--sim", "1"]) end
      assert_raise Mix.Error, ~r/bad option --nope\nusage: iex -S mix dolphin.console/, fn -> Task.run(["--nope"]) end
      assert Dolphin.Sim.vehicles() == []
    end
  end

  describe "start/1" do
    setup do
      links = DynamicSupervisor.which_children(Dolphin.Link.Supervisor)

      on_exit(fn ->
        Dolphin.Test.GroundStation.forget_vehicles()
        for {_, pid, _, _} <- DynamicSupervisor.which_children(Dolphin.Link.Supervisor) -- links, do: DynamicSupervisor.terminate_child(Dolphin.Link.Supervisor, pid)
      end)
    end

    test "simulated vehicles on a local link, known to the fleet before the console opens" do
      Dolphin.Fleet.set_source({Dolphin.Fleet.MAVLinkSource, nil})
      assert {:ok, banner} = Task.start(sim: 2, speedup: 20.0)
      assert banner =~ ~r/^Dolphin console \(speed-up 20x\)\n  2 simulated vehicle\(s\) \[1, 2\] on 127\.0\.0\.1:\d+\n/
      assert banner =~ "h Dolphin.Console"
      known = for %{vehicle: v} <- Dolphin.Fleet.vehicles(), v.type != nil, do: v.id
      assert Enum.sort(known) == [1, 2]
    end

    test "--tlog FILE: a file that is there is replaced, and the banner says so", %{tmp_dir: dir} do
      tlog = Path.join(dir, "console.tlog")
      File.write!(tlog, "an older session")
      assert {:ok, banner} = Task.start(connect: "udpin:127.0.0.1:0", tlog: tlog)
      assert banner =~ "\n  telemetry log: #{tlog} (replaces the file that was there)\n"
      refute File.read!(tlog) =~ "an older session"
    end

    test "a link that cannot be opened is an error" do
      assert "--connect carrier-pigeon:1: " <> _ = message(Task.start(connect: "carrier-pigeon:1"))
    end
  end

  # --- a real IEx session --------------------------------------------------------

  # `iex -S mix dolphin.console` in its own BEAM, on a terminal (util-linux
  # `script` gives it one; plain pipes otherwise), driven line by line as an
  # operator would.
  @tag :iex_session
  @tag timeout: 300_000
  test "an IEx session: list vehicles, take off and land one, run and stop a script", %{tmp_dir: dir} do
    # Two copters and a boat, which carries a sonar by the fleet file.
    fleet = Path.join(dir, "fleet.json")
    File.write!(fleet, ~s({"vehicles": [{"id": 3, "airframe": "boat", "payloads": ["sonar"]}]}))
    port = open_session("iex -S mix dolphin.console --sim copter:2,boat:1 --speedup 20 --fleet #{fleet}")

    banner = wait_for(port, ~r/iex\(1\)> /, 120_000)
    assert banner =~ "Dolphin console (speed-up 20x)"
    assert banner =~ "payloads of 1 vehicle(s) from #{fleet}"
    assert banner =~ ~r/3 simulated vehicle\(s\) \(2 copter, 1 boat\) \[1, 2, 3\] on 127\.0\.0\.1:\d+/

    # The helpers are imported (by .iex.exs), with their docs.
    assert ieval(port, "h vehicles") =~ "The fleet at a glance"
    # So are the script language's readers and values (.iex.exs too), live.
    assert ieval(port, "h battery") =~ "The remaining battery of a one-vehicle set"
    poll(port, "IO.inspect(battery(1))", &(&1 =~ ~r/^1\.0$/m))

    table = ieval(port, "vehicles()")
    assert table =~ ~r/^ID\s+TYPE\s+AIRFRAME\s+MODE\s+ARMED/m
    assert table =~ ~r/^ 1  uav\s+copter\s+STABILIZE\s+no /m
    assert table =~ ~r/^ 2  uav\s+copter\s+STABILIZE\s+no /m
    assert table =~ ~r/^ 3  usv\s+boat\s+MANUAL\s+no /m
    # The boat is picked by its airframe and the payload the fleet file gave it.
    poll(port, ~s|IO.inspect(Dolphin.Fleet.vehicles() \|> Enum.filter(&(:sonar in &1.vehicle.payloads)) \|> Enum.map(&{&1.vehicle.id, &1.vehicle.airframe}))|, &(&1 =~ "[{3, :boat}]"))

    assert ieval(port, "takeoff(1, 10)") =~ "vehicle 1: take-off to 10.0 m above home accepted"
    poll(port, "vehicles()", fn t -> altitude(t, 1) >= 9.0 end)

    assert ieval(port, "land(1)") =~ "vehicle 1: land accepted"
    poll(port, "vehicles()", fn t -> t =~ ~r/^ 1  uav\s+copter\s+LAND\s+no /m end)

    script = Path.join(dir, "patrol.exs")

    File.write!(script, """
    use Dolphin.Script
    v = pick(id: 2, timeout: seconds(30))
    message("patrolling " <> ask("Where?"))
    execute %{v => mission "Patrol" do
      take_off location(40.444233, -7.375234, 850)
      move_and_loiter_pos 60, 0, 0, 20
    end}
    """)

    # What a script prints comes when it comes: within a line's output or after it.
    started = ieval(port, ~s|run("#{script}")|)
    [_, id] = Regex.run(~r/run (\d+) started: script /, started)
    seen_or_wait(port, started, ~r/run #{id} asks: Where\?/)
    answered = ieval(port, ~s|answer("north")|)
    assert answered =~ ~s(answered run #{id}'s "Where?": "north")
    seen_or_wait(port, answered, ~r/\[run #{id}\] patrolling north/)

    tree = poll(port, "tasks()", &(&1 =~ ~r/mission "Patrol"  vehicle 2\s+item \d\/2/))
    assert tree =~ ~r/^run #{id} script .*patrol\.exs/m
    assert ieval(port, "land(2)") =~ "vehicle 2 is flying task"

    stopping = ieval(port, "stop(#{id})")
    assert stopping =~ "stopping run #{id} (script "
    seen_or_wait(port, stopping, ~r/run #{id} script .*patrol\.exs: stopped: its tasks were stopped, vehicles hold/)
    assert ieval(port, "tasks()") =~ "no tasks running"

    # The mission the script uploaded, as many rows as the heading says.
    downloaded = ieval(port, "download(2)")
    assert downloaded =~ "vehicle 2 holds 3 items: home (item 0) and 2 mission items (items 1 to 2)"
    assert length(Regex.scan(~r/^\s+\d (home|[A-Z_]+) /m, downloaded)) == 3

    Port.command(port, "System.halt()\n")
    assert_receive {^port, {:exit_status, 0}}, 30_000
  end

  # `iex -S mix dolphin.run`: the script runs in the background, the console stays usable.
  @tag :iex_session
  @tag timeout: 300_000
  test "iex -S mix dolphin.run: the console works while the script runs, and answers its ask", %{tmp_dir: dir} do
    script = Path.join(dir, "hop.exs")

    File.write!(script, """
    use Dolphin.Script
    v = pick(timeout: seconds(30))
    message("going " <> ask("Which way?"))
    # The hop lasts until the operator answers a second question: tasks() sees
    # it in flight however slowly a loaded machine runs this session.
    hop = mission "Hop" do
      take_off location(40.444233, -7.375234, 840)
      move 40, 0, 0
      return_home_and_loiter()
    end
    back = action do post(:back, ask("Back?")) end
    execute (until(hop, poll(:back)) |> on(v)) ||| back
    message("hop done")
    """)

    port = open_session("iex -S mix dolphin.run #{script} --sim 1 --speedup 20 --no-tlog")
    wait_for(port, ~r/iex\(1\)> /, 120_000)
    poll(port, "vehicles()", &(&1 =~ ~r/^ 1  uav\s+copter /m))
    # The script's question waits in tasks() until answered; then it flies and ends.
    poll(port, "tasks()", &(&1 =~ "Which way?"))
    answered = ieval(port, ~s|answer("north")|)
    seen_or_wait(port, answered, ~r/message: going north/)
    poll(port, "tasks()", &(&1 =~ ~r/mission "Hop"  vehicle 1/ and &1 =~ "Back?"))
    back = ieval(port, ~s|answer("now")|)
    seen_or_wait(port, back, ~r/message: hop done/)
    poll(port, "tasks()", &(&1 =~ "no tasks running"))
    Port.command(port, "System.halt()\n")
    assert_receive {^port, {:exit_status, 0}}, 30_000
  end

  defp open_session(command) do
    root = File.cwd!()
    env = [{~c"MIX_ENV", ~c"test"}, {~c"LANG", ~c"C.UTF-8"}]

    {exe, args} =
      case System.find_executable("script") do
        nil -> {System.find_executable("sh"), ["-c", command]}
        script -> {script, ["-q", "-e", "-c", command, "/dev/null"]}
      end

    port = Port.open({:spawn_executable, exe}, [:binary, :exit_status, :stderr_to_stdout, args: args, cd: root, env: env])
    Process.put(:session_output, "")
    Dolphin.Test.MixCommand.kill_on_exit(port)

    port
  end

  # Everything the session printed, without terminal escapes and carriage returns.
  defp receive_output(port, timeout) do
    receive do
      {^port, {:data, data}} ->
        clean = data |> String.replace(~r/\e\[[0-9;?]*[A-Za-z]/, "") |> String.replace("\r", "")
        Process.put(:session_output, Process.get(:session_output) <> clean)
        :data

      {^port, {:exit_status, status}} ->
        flunk("the IEx session ended (status #{status}):\n#{Process.get(:session_output)}")
    after
      timeout -> :timeout
    end
  end

  # Waits (bounded) until the output from the mark on matches; moves the mark past the match.
  defp wait_for(port, pattern, bound) do
    deadline = System.monotonic_time(:millisecond) + bound
    do_wait(port, pattern, deadline)
  end

  defp do_wait(port, pattern, deadline) do
    mark = Process.get(:session_mark, 0)
    output = Process.get(:session_output)
    rest = binary_part(output, mark, byte_size(output) - mark)

    case Regex.run(pattern, rest, return: :index) do
      [{at, len} | _] ->
        Process.put(:session_mark, mark + at + len)
        binary_part(rest, 0, at + len)

      nil ->
        left = deadline - System.monotonic_time(:millisecond)
        if left <= 0, do: flunk("no #{inspect(pattern)} in the IEx session's output:\n#{rest}")
        receive_output(port, left)
        do_wait(port, pattern, deadline)
    end
  end

  # Evaluates a line in the session; returns what it printed. The markers are
  # built at run time so that the terminal's echo of the line never matches them.
  defp ieval(port, code, bound \\ 60_000) do
    k = System.unique_integer([:positive])
    Port.command(port, ~s|IO.puts("@@" <> "#{k}"); #{code}; IO.puts("@@end" <> "#{k}")\n|)
    wait_for(port, ~r/^@@#{k}$/m, bound)
    text = wait_for(port, ~r/^@@end#{k}$/m, bound)
    text |> String.replace(~r/@@end#{k}$/, "") |> String.trim_leading("\n")
  end

  defp seen_or_wait(port, text, pattern), do: text =~ pattern or wait_for(port, pattern, 60_000)

  # Evaluates a line again (bounded) until what it prints satisfies `fun`.
  defp poll(port, code, fun, tries \\ 150) do
    text = ieval(port, code)

    cond do
      fun.(text) -> text
      tries == 0 -> flunk("#{code} never printed what was expected; last:\n#{text}")
      true -> Process.sleep(200) && poll(port, code, fun, tries - 1)
    end
  end

  defp altitude(table, id) do
    case Regex.run(~r/^\s*#{id}  uav\s+copter .*?\s(-?\d+\.\d) m  /m, table) do
      [_, alt] -> String.to_float(alt)
      nil -> -1.0
    end
  end

  defp message(result) do
    assert {:error, %Dolphin.CommandLineError{} = e} = result
    Exception.message(e)
  end
end
