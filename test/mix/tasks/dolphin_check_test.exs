defmodule Mix.Tasks.Dolphin.CheckTest do
  # The --connect tests' vehicles in a Dolphin.Instance of the test's own: async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Mix.Tasks.Dolphin.Check, as: Task

  @dir "test/fixtures/check"

  defp main(argv) do
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    code = Task.main(argv, out: out, err: err)
    {code, StringIO.flush(out), StringIO.flush(err)}
  end

  test "exit 0 and a summary for a sound script" do
    assert {0, out, ""} = main([Path.join(@dir, "ok.exs"), "--fleet", Path.join(@dir, "fleet.json")])
    assert out =~ ~s(mission "Hop" on vehicle)
    assert out =~ "0 error(s)"
  end

  test "exit 1 with one line per finding, file:line: severity" do
    assert {1, out, _} = main([Path.join(@dir, "bad_mission.exs"), "--fleet", Path.join(@dir, "fleet.json")])
    assert out =~ "bad_mission.exs:18: error: mission \"Bad\" on vehicle 212: no take-off"
  end

  test "--json gives one object" do
    assert {1, out, _} = main([Path.join(@dir, "no_pick.exs"), "--sim", "1", "--json"])
    assert %{"ok" => false, "findings" => [%{"kind" => "pick", "line" => 3} | _]} = :jiffy.decode(out, [:return_maps])
  end

  test "mix dolphin.run checks first and refuses to fly on errors" do
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    assert 1 = Mix.Tasks.Dolphin.Run.main([Path.join(@dir, "bad_mission.exs"), "--sim", "1", "--no-tlog"], out: out, err: err, plain: true)
    {_, text} = StringIO.contents(out)
    assert text =~ "bad_mission.exs:17: error: no vehicle of the fleet can serve this pick"
    assert text =~ "the pre-flight check found errors: nothing flies (--no-check to fly anyway)"
    # Nothing was started.
    assert Dolphin.Vehicles.list() == []
  end

  test "mix dolphin.run takes --no-check" do
    assert {:ok, _, opts} = Mix.Tasks.Dolphin.Run.parse([Path.join(@dir, "ok.exs"), "--sim", "1", "--no-check"])
    assert opts[:no_check]
    {:ok, out} = StringIO.open("")
    # --fake tries a script's logic on the fake platform: no missions, no check.
    {:ok, script} = Dolphin.Script.compile(Path.join(@dir, "bad_mission.exs"))
    assert :ok = Dolphin.CLI.Run.check(script, [fake: 1], out)
    assert :ok = Dolphin.CLI.Run.check(script, [sim: 1, no_check: true], out)
    Dolphin.Script.purge(script)
    assert {_, ""} = StringIO.contents(out)
  end

  describe "--connect" do
    test "checks against the vehicles that answer on the link, then lets them go" do
      {:ok, socket} = :gen_udp.open(0, ip: {127, 0, 0, 1})
      {:ok, port} = :inet.port(socket)
      :ok = :gen_udp.close(socket)
      {:ok, [221]} = Dolphin.Sim.start(count: 1, first_sysid: 221, gcs: port)

      assert {0, out, _} = main([Path.join(@dir, "ok.exs"), "--connect", "udpin:127.0.0.1:#{port}", "--wait", "3"])
      assert out =~ ~s(mission "Hop" on vehicle 221)
      # The link is closed and the vehicle forgotten: the stand-in had its id.
      assert Dolphin.Vehicles.whereis(221) == nil
    end

    test "no vehicle answering is a failure that says so" do
      {:ok, socket} = :gen_udp.open(0, ip: {127, 0, 0, 1})
      {:ok, port} = :inet.port(socket)
      :ok = :gen_udp.close(socket)
      assert {1, "", err} = main([Path.join(@dir, "ok.exs"), "--connect", "udpin:127.0.0.1:#{port}", "--wait", "0.2"])
      assert err =~ "no vehicle reported its position within"
    end
  end

  describe "as a command, in a fresh VM" do
    # `mix dolphin.check` in its own OS process: atoms and modules this test
    # VM has long loaded do not exist there yet.
    @describetag :tmp_dir

    test "the fleet file format of the README and `mix help dolphin.check` is read" do
      {status, out} = run_mix(["dolphin.check", Path.join(@dir, "ok.exs"), "--fleet", Path.join(@dir, "fleet.json")])
      assert status == 0, out
      assert out =~ ~s(mission "Hop" on vehicle 211)
      assert out =~ "0 error(s)"
    end

    test "missions a run would fail on are errors: exit 1, each with its line" do
      {status, out} = run_mix(["dolphin.check", Path.join(@dir, "cannot_fly.exs"), "--sim", "1"])
      assert status == 1, out
      assert out =~ ~s(cannot_fly.exs:26: error: mission "Empty" on vehicle 1: nothing to fly)
      assert out =~ ~s(cannot_fly.exs:27: error: mission "Only home" on vehicle 1: nothing to fly)
      assert out =~ ~s(cannot_fly.exs:28: error: mission "Only speed" on vehicle 1: no take-off)
      assert out =~ ~s<cannot_fly.exs:29: error: mission "Flat" on vehicle 1: item 1 (NAV_TAKEOFF) has a pitch of 860°>
      assert out =~ ~s<cannot_fly.exs:29: error: mission "Flat" on vehicle 1: item 1 (NAV_TAKEOFF) goes to 820 m above sea level>
      assert out =~ "5 error(s)"
    end

    test "each airframe's limits: a plane's survey it cannot turn into, a submarine deeper than --max-depth" do
      args = ["dolphin.check", Path.join(@dir, "airframe_limits.exs"), "--fleet", Path.join(@dir, "airframe_limits.json")]
      {status, out} = run_mix(args)
      assert status == 1, out

      assert out =~
               ~s<airframe_limits.exs:23: error: mission "Strip" on vehicle 41: survey_area(1500, 600, 60, :north_east) puts its passes 60 m apart, and a plane at 22.0 m/s turns no tighter than a 49 m radius>

      assert out =~ ~s<airframe_limits.exs:23: error: mission "Trench" on vehicle 42: item 1 (NAV_WAYPOINT) is 150 m deep (limit 100 m)>
      assert out =~ "2 error(s)"

      {status, out} = run_mix(args ++ ["--max-depth", "200"])
      assert status == 1, out
      refute out =~ "deep"
      assert out =~ "1 error(s)"
    end

    test "a loop in which nothing waits is an error with the loop's line" do
      {status, out} = run_mix(["dolphin.check", Path.join(@dir, "busy_loop.exs"), "--sim", "1"])
      assert status == 1, out
      assert out =~ "busy_loop.exs:7: error: nothing in this `forever` loop waits"
      refute out =~ "still running"
    end

    test "every type, no type, and any payload; a broken file is told in its own terms", %{tmp_dir: dir} do
      fleet = Path.join(dir, "fleet.json")

      File.write!(fleet, ~s({"vehicles": [
        {"id": 1, "type": "ugv", "payloads": ["sidescan_sonar"], "position": [40.444233, -7.375234, 820]},
        {"id": 2, "position": [40.444233, -7.375234, 820]},
        {"id": 3, "type": "usv", "position": [40.444233, -7.375234, 820]}]}))

      {status, out} = run_mix(["dolphin.check", Path.join(@dir, "ok.exs"), "--fleet", fleet])
      assert status == 0, out
      assert out =~ ~s(mission "Hop" on vehicle 2)

      File.write!(fleet, ~s({"vehicles": [\n  {"id": 1, "type": "uav", "battery": 7},\n  {"id": 1, "type": "ugv", "position": [40.4, -7.3, 820]}\n]}))
      {status, out} = run_mix(["dolphin.check", Path.join(@dir, "ok.exs"), "--fleet", fleet])
      assert status == 2, out
      assert out =~ "fleet file #{fleet}: 3 problems:"
      assert out =~ ~s(vehicle #1: "battery" must be a number from 0.0 to 1.0, got 7)
      assert out =~ ~s(vehicle #1: "position" is missing)
      assert out =~ "vehicle #2: id 1 is given twice"

      File.write!(fleet, ~s({"vehicles": [\n))
      {status, out} = run_mix(["dolphin.check", Path.join(@dir, "ok.exs"), "--fleet", fleet])
      assert status == 2, out
      assert out =~ "fleet file #{fleet}: not valid JSON: the text ends in the middle of a value (byte 15, line 2, column 1)"
      refute out =~ ~r/truncated_json|unknown type/
    end
  end

  # Runs a mix task in its own OS process; its exit status and output. A
  # check takes a moment: the bound is for a loaded machine, not a measure.
  defp run_mix(args) do
    env = [{~c"MIX_ENV", ~c"test"}, {~c"LANG", ~c"C.UTF-8"}, {~c"LC_ALL", ~c"C.UTF-8"}]
    port = Port.open({:spawn_executable, System.find_executable("mix")}, [:binary, :exit_status, :stderr_to_stdout, args: args, cd: File.cwd!(), env: env])
    {:os_pid, os_pid} = Port.info(port, :os_pid)
    on_exit(fn -> System.cmd("kill", ["-9", Integer.to_string(os_pid)], stderr_to_stdout: true) end)
    collect(port, "")
  end

  defp collect(port, out) do
    receive do
      {^port, {:data, data}} -> collect(port, out <> data)
      {^port, {:exit_status, status}} -> {status, out}
    after
      120_000 -> flunk("the command did not end within 120 s:\n#{out}")
    end
  end

  test "exit 2 on bad usage" do
    assert {2, _, err} = main(["nope.exs"])
    assert err =~ "no such script: nope.exs"
    assert {2, _, err} = main([Path.join(@dir, "ok.exs"), "--sim", "1", "--fleet", "x.json"])
    assert err =~ "only one of --sim, --fleet and --connect"
    assert {2, _, _} = main([Path.join(@dir, "ok.exs"), "--bogus"])
    assert {2, _, err} = main([Path.join(@dir, "ok.exs"), "--connect", "carrier-pigeon:1"])
    assert err =~ "--connect carrier-pigeon:1"
    assert {2, _, err} = main([Path.join(@dir, "ok.exs"), "--fleet", Path.join(@dir, "ok.exs")])
    assert err =~ "fleet file"
  end
end
