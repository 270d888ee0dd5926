defmodule Dolphin.ConsoleTest do
  # The console's helpers against simulated copters over UDP on 127.0.0.1.
  # Changes the clock speed-up and uses the application's fleet: not async.
  use ExUnit.Case, async: false

  import Dolphin.Console

  alias Dolphin.{Engine, Mission, Sim, Vehicles}
  alias Dolphin.Test.Wait

  @moduletag :tmp_dir
  @speedup 20
  @home Dolphin.Geo.location(40.444233, -7.375234, 820)
  @fixtures Path.expand("../fixtures/console", __DIR__)

  setup do
    Dolphin.Fleet.set_source({Dolphin.Fleet.MAVLinkSource, nil})
    port = Dolphin.Test.GroundStation.open()
    {:ok, [1, 2]} = Sim.start(count: 2, gcs: port, speedup: @speedup, camera: true)
    Wait.until(fn -> Enum.all?([1, 2], &match?({:ok, %{home: %{}, position: %{}, battery: b}} when b != nil, Vehicles.state(&1))) end)
    Wait.until(fn -> Enum.all?(Dolphin.Fleet.vehicles(), & &1.vehicle.connected?) and length(Dolphin.Fleet.vehicles()) == 2 end)

    # What the helpers print, and what the console's runs print later, goes to a
    # device of the test's own (as a console's group leader).
    {:ok, io} = StringIO.open("")
    gl = Process.group_leader()
    Process.group_leader(self(), io)

    on_exit(fn ->
      for run <- Dolphin.Console.Runs.list(), do: Dolphin.Console.Runs.stop(run.id)
      for run <- Engine.runs(), do: Engine.stop(run.run)
      Wait.until(fn -> Engine.runs() == [] and Dolphin.Console.Runs.list() == [] end)
    end)

    on_exit(fn -> Process.group_leader(self(), gl) end)
    %{io: io}
  end

  # What was printed since the last call (and not yet taken by await_out/2).
  defp out(io), do: (Process.delete(:left) || "") <> StringIO.flush(io)

  # Waits until what is printed matches; returns the text up to the end of
  # the line of the match and leaves the rest for the next out/1 or await_out/2.
  defp await_out(io, pattern, tries \\ 1_500) do
    text = out(io)

    case Regex.run(if(is_binary(pattern), do: ~r/#{Regex.escape(pattern)}/, else: pattern), text, return: :index) do
      [{at, len} | _] ->
        # To the end of the line of the match (Regex indices are bytes).
        upto =
          case :binary.match(text, "\n", scope: {at + len, byte_size(text) - at - len}) do
            {nl, 1} -> nl + 1
            :nomatch -> byte_size(text)
          end

        Process.put(:left, binary_part(text, upto, byte_size(text) - upto))
        binary_part(text, 0, upto)

      nil when tries == 0 ->
        flunk("no output matching #{inspect(pattern)} in:\n#{text}")

      nil ->
        Process.put(:left, text)
        Process.sleep(20)
        await_out(io, pattern, tries - 1)
    end
  end

  # Waits until every pattern was printed, in any order; returns all the text seen.
  defp await_all(io, patterns, tries \\ 1_500) do
    text = out(io)

    cond do
      Enum.all?(patterns, &(text =~ &1)) -> text
      tries == 0 -> flunk("no output matching all of #{inspect(patterns)} in:\n#{text}")
      true -> wait_more(text) && await_all(io, patterns, tries - 1)
    end
  end

  defp wait_more(text) do
    Process.put(:left, text)
    Process.sleep(20)
  end

  defp patrol do
    import Dolphin.DSL.Mission

    mission "Patrol" do
      home(@home)
      take_off(%{@home | h: 850})
      move_and_loiter_pos(60, 0, 0, 20)
    end
  end

  test "vehicles() shows the fleet; helpers return IEx's no-result", %{io: io} do
    assert vehicles() == IEx.dont_display_result()
    [header, one, two] = String.split(out(io), "\n", trim: true)
    assert header =~ ~r/^ID\s+TYPE\s+AIRFRAME\s+MODE\s+ARMED\s+BATTERY\s+POSITION\s+ALT\s+LINK\s+SEEN\s+TASK$/
    assert one =~ ~r/^ 1  uav\s+copter\s+STABILIZE\s+no\s+100 %  40\.44\d+, -7\.37\d+\s+0\.0 m  100 %(, \d+ ms)?\s+\d+ ms ago\s+-$/
    assert two =~ ~r/^ 2  uav\s+copter/
  end

  test "bad ids and lost vehicles are refused, and nothing is sent", %{io: io} do
    arm("1")
    assert out(io) =~ ~s{a vehicle is given by its id as vehicles() lists it (a system id, or a name "SYSID@NETWORK" for another vehicle with that system id), got: "1"}
    takeoff(9, 10)
    assert out(io) == "no vehicle 9: the known vehicles are 1, 2 (see vehicles())\n"
    takeoff(1, -5)
    assert out(io) =~ "takeoff: an altitude is a number of metres above home, more than 0, got: -5"
    goto(1, 95, 0, 10)
    assert out(io) =~ "goto: latitude must be degrees in -90..90"
    mode(1, 3)
    assert out(io) =~ "mode: a mode is a name"
    arm(1, wiat: 0)
    assert out(io) =~ "unknown option :wiat; options are :force, :wait"
    arm(1, wait: :forever)
    assert out(io) =~ "vehicle 1: wait: takes milliseconds"
    mode(1, "HOVER_LIKE_A_BEE")
    assert out(io) =~ ~s(mode: no flight mode is called "HOVER_LIKE_A_BEE")
    mode(1, :manual)
    assert out(io) =~ ~r/vehicle 1: mode MANUAL refused: .*no mode :manual on this vehicle/

    :ok = Sim.stop(2)
    Wait.until(fn -> match?({:ok, %{connected?: false}}, Vehicles.view(2)) end)
    arm(2)
    assert out(io) =~ ~r/^vehicle 2 is lost \(nothing heard for .+\): nothing sent; check its link/
    watch(2)
    assert out(io) =~ "vehicle 2 is lost"
    # What the ground station has of it can still be read.
    messages(2)
    assert out(io) =~ "vehicle 2 is lost; its last messages:"
    vehicles()
    assert out(io) =~ ~r/\n 2  uav\s+copter.*LOST /
    {:ok, one} = Vehicles.state(1)
    refute one.armed
  end

  test "a watch shows a vehicle lost while it is watched", %{io: io} do
    # The watch runs in a process of its own (linked: it ends with the
    # test), printing to the test's device.
    watcher = Task.async(fn -> watch(2, every: 100, timeout: 120_000, keys: false) end)
    refute await_out(io, ~r/^\s+\d+\.\d s  \S+.*mission/m) =~ "LOST"
    :ok = Sim.stop(2)
    assert await_out(io, ~r/  LOST$/m) =~ ~r/^\s+\d+\.\d s  .*  LOST$/m
    Task.shutdown(watcher, :brutal_kill)
  end

  test "take off, go to a point, hold, land; messages, watch, events", %{io: io} do
    takeoff(1, 10)
    text = out(io)
    assert text =~ "vehicle 1: mode GUIDED accepted"
    assert text =~ "vehicle 1: arm accepted"
    assert text =~ "vehicle 1: take-off to 10.0 m above home accepted"
    Wait.until(fn -> match?({:ok, %{position: %{relative_alt: a}}} when a > 9.5, Vehicles.state(1)) end)

    takeoff(1, 20)
    assert out(io) =~ ~r/^vehicle 1 is flying already \(\d+\.\d m above home\): goto\(1, lat, lon, alt\) moves it$/m
    disarm(1)
    assert out(io) =~ "vehicle 1 is in the air: disarming would make it fall"
    mode(1, :loiter)
    assert out(io) =~ "LOITER is flown by a pilot's sticks"

    goto(1, 40.4444, -7.3754, 15)
    assert out(io) =~ "vehicle 1: go to 40.444400, -7.375400 at 15.0 m above home accepted"
    Wait.until(fn -> match?({:ok, %{position: %{relative_alt: a}}} when a > 14.5, Vehicles.state(1)) end)
    hold(1)
    assert out(io) =~ "vehicle 1 holds already (GUIDED)"
    mode(1, "brake")
    assert out(io) =~ "vehicle 1: mode BRAKE accepted"

    watch(1, every: 100, timeout: 300, keys: false)
    [first | rest] = String.split(out(io), "\n", trim: true)
    assert first == "watching vehicle 1 (stops by itself after 300 ms)"
    assert List.last(rest) == "watch ended (timeout)"
    assert Enum.any?(rest, &(&1 =~ ~r/^\s+\d+\.\d s  (BRAKE|GUIDED)\s+ARMED\s+\[#+\s*\]\s+\d+ %  40\.44/))

    land(1)
    assert out(io) =~ "vehicle 1: land accepted"
    Wait.until(fn -> match?({:ok, %{armed: false}}, Vehicles.state(1)) end, 1_000)

    messages(1)
    assert out(io) =~ ~r/INFO\s+Arming motors/
    events(50, vehicle: 1)
    text = out(io)
    assert text =~ ~r/\[\s*\d+\.\d s\] vehicle 1 armed/
    assert text =~ "vehicle 1 mode LAND"
    refute text =~ "vehicle 2"
    events(2, event: [:armed, :disarmed])
    assert out(io) =~ ~r/vehicle 1 armed\n.*vehicle 1 disarmed\n$/
    events(0)
    assert out(io) =~ "events: a count is a positive integer, got: 0"
  end

  test "parameters: one read, one set and read back, those whose names match, a name the vehicle does not have", %{io: io} do
    param(1, "WPNAV_SPEED")
    assert out(io) =~ ~r/^vehicle 1: WPNAV_SPEED = \d+$/m
    set_param(1, "WPNAV_SPEED", 750)
    assert out(io) =~ ~r/^vehicle 1: WPNAV_SPEED set to 750$/m
    param(1, "WPNAV_SPEED")
    assert out(io) =~ ~r/^vehicle 1: WPNAV_SPEED = 750$/m

    params(1, "FENCE_")
    text = out(io)
    assert text =~ ~r/^FENCE_RADIUS\s+150$/m
    assert [_, shown, all] = Regex.run(~r/^(\d+) of (\d+) parameters$/m, text)
    assert String.to_integer(shown) >= 7 and String.to_integer(all) > String.to_integer(shown)
    refute text =~ "WPNAV"

    param(1, "WPNAV_SPED")
    assert out(io) =~ ~r/vehicle 1 has no parameter WPNAV_SPED .*WPNAV_SPEED/
    set_param(1, "WPNAV_SPEED", "fast")
    assert out(io) =~ ~s(set_param takes a number, got: "fast")
  end

  test "a task run: the tree, a vehicle it flies refused, then taken over with force", %{io: io} do
    run(patrol(), on: 2)
    [_, id] = Regex.run(~r/run (\d+) started: mission "Patrol" \(tasks\(\) shows it, stop\(\d+\) stops it\)\n$/, out(io))
    id = String.to_integer(id)

    Wait.until(fn -> match?({:ok, %{mode: :auto, mission: %{current: 2}}}, Vehicles.state(2)) end, 1_000)
    # The tree shows the mission's progress as its task heard it, which may
    # come a moment after the vehicle's own view.
    text =
      Wait.until(fn ->
        tasks()
        text = out(io)
        if text =~ ~r/└─ \d+ mission "Patrol"  vehicle 2\s+item 2\/2/, do: text
      end)

    assert text =~ ~s{run #{id} task mission "Patrol" (started from this console, running for}
    vehicles()
    assert out(io) =~ ~r/\n 2  uav\s+copter\s+AUTO .* \d+ mission "Patrol" \(run #{id}\)\n/

    land(2)
    assert out(io) =~ ~r/^vehicle 2 is flying task \d+ mission "Patrol" \(run #{id}\): nothing sent\. Add force: true/
    upload(2, patrol())
    assert out(io) =~ "vehicle 2 is flying task"
    {:ok, st} = Vehicles.state(2)
    assert st.mode == :auto

    land(2, force: true)
    # The run's end may be printed before or after the land command's answer.
    await_all(io, [
      ~r/vehicle 2: stopping task \d+ mission "Patrol" \(run #{id}\) first; the vehicle holds\n/,
      "vehicle 2: land accepted",
      ~r/run #{id} task mission "Patrol": (done|stopped)/
    ])

    Wait.until(fn -> match?({:ok, %{armed: false}}, Vehicles.state(2)) end, 1_000)
    stop(id)
    assert out(io) =~ "stop: nothing runs with id #{id} (tasks() shows the ids)"
    tasks()
    assert out(io) == "no tasks running\n"
  end

  test "a script run from the console asks, is answered, and stops on stop/1", %{io: io, tmp_dir: dir} do
    path = Path.join(dir, "patrol.exs")

    File.write!(path, """
    use Dolphin.Script
    v = pick(id: 2, timeout: seconds(30))
    area = ask("Which area?")
    message("patrolling \#{area}")
    execute %{v => mission "Patrol" do
      take_off location(40.444233, -7.375234, 850)
      move_and_loiter_pos 60, 0, 0, 20
    end}
    """)

    answer("too early")
    assert out(io) == "answer: no script is asking anything now\n"

    run(path)
    # The script may ask before run/2 says it started.
    text = await_all(io, [~r/run \d+ started: script .*patrol.exs/, ~r/run \d+ asks: Which area\?/])
    [_, id] = Regex.run(~r/run (\d+) started: script .*patrol.exs/, text)
    assert text =~ "run #{id} asks: Which area?  (answer(\"...\") to answer)"
    tasks()
    assert out(io) =~ ~s{waiting for an answer: run #{id} asks "Which area?" (answer/1)}
    answer("north")
    # The script may print its message before answer/1 says it answered.
    await_all(io, [~s{answered run #{id}'s "Which area?": "north"}, "[run #{id}] patrolling north"])

    Wait.until(fn -> match?({:ok, %{mode: :auto, mission: %{current: 2}}}, Vehicles.state(2)) end, 1_000)
    # The task's progress comes from its executor, after the vehicle's state shows it: listed until it does.
    text =
      Wait.until(fn ->
        tasks()
        text = out(io)
        if text =~ "item 2/2", do: text
      end)

    assert text =~ ~r/^run #{id} script .*patrol.exs\s+running for .+\n└─ run \d+\n   └─ \d+ mission "Patrol"  vehicle 2\s+item 2\/2/

    stop(String.to_integer(id))
    await_all(io, ["stopping run #{id} (script ", ~r/run #{id} script .*patrol.exs: stopped: its tasks were stopped, vehicles hold/])
    Wait.until(fn -> match?({:ok, %{mode: m, armed: true}} when m in [:brake, :guided], Vehicles.state(2)) end)
    tasks()
    assert out(io) == "no tasks running\n"
  end

  test "run refuses what it cannot run", %{io: io, tmp_dir: dir} do
    run(Path.join(dir, "nope.exs"))
    assert out(io) =~ "run: no such script: "
    bad = Path.join(dir, "bad.exs")
    File.write!(bad, "use Dolphin.Script\npik(type: :uav)\n")
    run(bad)
    assert out(io) =~ ~r/run: .*bad.exs:2: undefined function pik\/1/
    run(42)
    assert out(io) =~ "run: takes a script's path or a task (a mission, a combinator...), got: 42"
    run(patrol(), on: [9])
    assert out(io) =~ "run: vehicle 9 is not free"
    run(patrol(), bogus: 1)
    assert out(io) =~ "run: unknown option :bogus; options are :on"
    stop(:all)
    assert out(io) =~ "stop: takes the id of a run or task"
    assert Dolphin.Console.Runs.list() == []
  end

  test "stop_all() stops the console's runs and the others; stop/1 stops one task", %{io: io} do
    stop_all()
    assert out(io) == "nothing is running\n"

    # A run started elsewhere, by a process that picked vehicle 1.
    test = self()

    other =
      spawn(fn ->
        {:ok, _} = Dolphin.Fleet.pick(Dolphin.Fleet, self(), id: 1)
        {:ok, run} = Engine.start(Engine.on(Engine.idle(3_600_000, name: "long wait"), [1]), [])
        send(test, {:other_run, run})
        Engine.await(run)
        Process.sleep(:infinity)
      end)

    on_exit(fn -> Process.exit(other, :kill) end)
    assert_receive {:other_run, other_run}, 5_000
    run(Engine.sequence([Engine.idle(3_600_000, name: "one"), Engine.idle(10, name: "two")]))
    [_, id] = Regex.run(~r/run (\d+) started/, out(io))
    Wait.until(fn -> Enum.any?(Engine.tasks(), &(&1.name == "one")) end)

    tasks()
    text = out(io)
    assert text =~ "run #{other_run}\n"
    assert text =~ ~r/run #{id} task sequence/

    one = Enum.find(Engine.tasks(), &(&1.name == "one"))
    stop(one.task_id)
    # (What the stop leads to may be printed before the stop's own line is read.)
    await_all(io, [~s{stopping task #{one.task_id} idle "one"; its parent goes on as if it had completed}, ~r/run #{id} task sequence .*: done/])

    run(Engine.idle(3_600_000, name: "three"))
    [_, id] = Regex.run(~r/run (\d+) started/, out(io))
    stop_all()
    await_all(io, ["stopping run #{id} (task idle \"three\"), run #{other_run}: their tasks stop and their vehicles hold", ~r/run #{id} task idle "three": stopped/])
    Wait.until(fn -> Engine.runs() == [] end)
  end

  test "upload a plan file, download it back and save it", %{io: io, tmp_dir: dir} do
    upload(1, Path.join(@fixtures, "relative.plan"))
    assert out(io) =~ ~s{vehicle 1: mission "relative" uploaded (6 items, home included)}

    saved = Path.join(dir, "back.plan")
    download(1, save: saved)
    text = out(io)
    # As many items as rows in the table below, home first.
    assert text =~ "vehicle 1 holds 6 items: home (item 0) and 5 mission items (items 1 to 5)\n"
    assert length(Regex.scan(~r/^\s+\d+ [A-Z_]+|^\s+0 home/m, text)) == 6
    assert text =~ ~r/\n\s+0 home\s/
    assert text =~ ~r/\n\s+1 NAV_TAKEOFF\s+40\.4442330, -7\.3752340, 20 m above home/
    assert text =~ ~s{\nmission "vehicle 1" do\n  home location(}
    assert text =~ "saved as #{saved}"
    assert {:ok, back} = Mission.from_plan(File.read!(saved))
    {:ok, sent} = Mission.from_plan(File.read!(Path.join(@fixtures, "relative.plan")))
    assert length(Mission.to_items(back)) == length(Mission.to_items(sent))

    upload(1, Path.join(dir, "none.plan"))
    assert out(io) =~ "upload: " <> Path.join(dir, "none.plan") <> ": no such file"
    upload(1, :nothing)
    assert out(io) =~ "upload: a mission is a %Dolphin.Mission{} or a .plan file's path"
  end
end
