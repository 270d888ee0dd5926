defmodule Mix.Tasks.Dolphin.PlanTest do
  # One test sets the Mix shell (global): not async.
  use ExUnit.Case, async: false

  alias Dolphin.Mission
  alias Mix.Tasks.Dolphin.Plan

  doctest Mix.Tasks.Dolphin.Plan

  @moduletag :tmp_dir
  @fixtures Path.expand("../../fixtures/console", __DIR__)
  @example Path.expand("../../../examples/single_vehicle.exs", __DIR__)

  defp eval_source(source) do
    {mission, _} = Code.eval_string("import Dolphin.DSL.Mission; import Dolphin.DSL.Values\n" <> source)
    mission
  end

  describe "export" do
    test "a script's mission, by name or by variable, as a plan QGroundControl reads", %{tmp_dir: dir} do
      out = Path.join(dir, "survey.plan")
      assert {:ok, text} = Plan.main(["export", @example, "Survey Area", out])
      assert text == "wrote #{out}: mission \"Survey Area\" (simple_mission), 3 items after home (QGroundControl: Plan, Open)"

      plan = :jiffy.decode(File.read!(out), [:return_maps])
      assert plan["fileType"] == "Plan"
      assert plan["mission"]["plannedHomePosition"] == [40.444233, -7.375234, 820.0]
      assert Enum.map(plan["mission"]["items"], & &1["command"]) == [22, 16, 17]

      by_var = Path.join(dir, "by_var.plan")
      assert {:ok, _} = Plan.main(["export", @example, "simple_mission", by_var])
      assert File.read!(by_var) == File.read!(out)
    end

    test "a file of missions; the plan's speeds", %{tmp_dir: dir} do
      out = Path.join(dir, "hop.plan")
      assert {:ok, _} = Plan.main(["export", Path.join(@fixtures, "missions.exs"), "Hop", out, "--cruise-speed", "12", "--hover-speed", "3"])
      plan = :jiffy.decode(File.read!(out), [:return_maps])
      assert {plan["mission"]["cruiseSpeed"], plan["mission"]["hoverSpeed"]} == {12.0, 3.0}
    end

    test "a mission without a home takes --home", %{tmp_dir: dir} do
      file = Path.join(dir, "nohome.exs")
      File.write!(file, "m = mission \"Away\" do\n  move 10, 0, 0\nend\n")
      out = Path.join(dir, "away.plan")
      why = message(Plan.main(["export", file, "Away", out]))

      assert why ==
               ~s|mission "Away" has no home, and no position of its own to take for one: give it one with `home location(LAT, LON, ALT)` in its block, or give the plan one with --home LAT,LON,ALT|

      assert {:ok, listed} = Plan.main(["list", file])
      assert listed =~ ~s|"Away" (m): cannot be made into items: mission "Away" has no home, and no position of its own|
      refute listed =~ "to_items"
      assert {:ok, _} = Plan.main(["export", file, "Away", out, "--home", "40.444233,-7.375234,820"])
      assert {:ok, m} = Mission.from_plan(File.read!(out))
      assert m.home == Dolphin.Geo.location(40.444233, -7.375234, 820.0)
    end

    test "no such mission: what the file defines, and what was skipped", %{tmp_dir: dir} do
      why = message(Plan.main(["export", @example, "Nope", Path.join(dir, "x.plan")]))
      assert why =~ ~s{no mission "Nope"; the file defines: "Return to base" (return_home), "Survey Area" (simple_mission)}
      assert why =~ "single_vehicle.exs:27: skipped (not a definition)"
      refute File.exists?(Path.join(dir, "x.plan"))
    end
  end

  describe "import" do
    test "as mission source that gives the plan's mission back" do
      file = Path.join(@fixtures, "relative.plan")
      assert {:ok, text} = Plan.main(["import", file])
      assert text =~ ~r/^# relative.plan: 5 commands\nmission "relative" do\n  home location\(40.444233, -7.375234, 820.0\)\n/
      assert text =~ "\n  speed 8.0, 1\n"
      {:ok, expected} = Mission.from_plan(File.read!(file), name: "relative")
      assert eval_source(text) == expected
      assert {:ok, named} = Plan.main(["import", file, "--name", "Hill"])
      assert named =~ ~s(mission "Hill" do)
    end

    test "QGroundControl's own plan, round trip through source" do
      file = Path.expand("../../fixtures/plans/serra_da_estrela.plan", __DIR__)
      assert {:ok, text} = Plan.main(["import", file])
      {:ok, expected} = Mission.from_plan(File.read!(file), name: "serra_da_estrela")
      assert Mission.to_items(eval_source(text)) == Mission.to_items(expected)
    end

    test "as items" do
      assert {:ok, text} = Plan.main(["import", Path.join(@fixtures, "relative.plan"), "--items"])
      lines = String.split(text, "\n")
      assert length(lines) == 6
      assert hd(lines) =~ ~r/^\s+0 home\s+40\.4442330, -7\.3752340, 820 m AMSL/
      assert Enum.at(lines, 1) =~ ~r/^\s+1 NAV_TAKEOFF\s+40\.4442330, -7\.3752340, 20 m above home/
      assert List.last(lines) =~ ~r/^\s+5 NAV_RETURN_TO_LAUNCH/
    end

    test "plans that cannot be read say why", %{tmp_dir: dir} do
      why = message(Plan.main(["import", Path.join(@fixtures, "complex.plan")]))
      assert why =~ ~s(only SimpleItem items are read)
      garbage = Path.join(dir, "garbage.plan")
      File.write!(garbage, "{not json")
      why = message(Plan.main(["import", garbage]))
      assert why =~ "garbage.plan: "
      why = message(Plan.main(["import", Path.join(dir, "none.plan")]))
      assert why =~ "no such plan file: "
      # Bad usage: the command line named a directory (the usage follows).
    [said | _usage] = String.split(message(Plan.main(["import", dir])), "\n")
    assert said == "#{dir} is a directory, not a plan file"
    end
  end

  test "list" do
    assert {:ok, text} = Plan.main(["list", Path.join(@fixtures, "missions.exs")])

    assert text ==
             Enum.join(
               [
                 ~s|"Inspection" (inspection): 4 items after home|,
                 ~s|"Leg 30-0" (tour[0]): 1 item after home|,
                 ~s|"Leg 0-30" (tour[1]): 1 item after home|,
                 ~s|"Hop" (line 13): 2 items after home|
               ],
               "\n"
             )
  end

  test "bad usage" do
    assert "no command given\nusage: mix dolphin.plan export" <> _ = message(Plan.main([]))
    assert "unknown command \"frob\"" <> _ = message(Plan.main(["frob"]))
    assert "export: wrong arguments" <> _ = message(Plan.main(["export", "a.exs"]))
    assert "bad option --bogus" <> _ = message(Plan.main(["import", "a.plan", "--bogus"]))
    assert "--home is no option of import" <> _ = message(Plan.main(["import", "a.plan", "--home", "1,2,3"]))
    assert "--home north: LAT,LON,ALT: degrees, degrees, metres above mean sea level" <> _ = message(Plan.main(["export", @example, "x", "o.plan", "--home", "north"]))
    assert "--home 91,0,0: the latitude 91 is not within -90..90" <> _ = message(Plan.main(["export", @example, "x", "o.plan", "--home", "91,0,0"]))
    assert "--cruise-speed 0: a speed in metres per second, more than 0" <> _ = message(Plan.main(["export", @example, "x", "o.plan", "--cruise-speed", "0"]))
    assert "--vehicle 0: a system id from 1 to 254" <> _ = message(Plan.main(["upload", "a.plan", "--connect", "udpin:127.0.0.1:14550", "--vehicle", "0"]))
    assert "--vehicle 1@: a system id from 1 to 254, or SYSID@NETWORK as vehicles() lists it" <> _ =
             message(Plan.main(["upload", "a.plan", "--connect", "udpin:127.0.0.1:14550", "--vehicle", "1@"]))
    assert "--timeout 0: a number of seconds, more than 0" <> _ = message(Plan.main(["upload", "a.plan", "--connect", "udpin:127.0.0.1:14550", "--timeout", "0"]))
    assert "--connect udpin:127.0.0.1:0: the port is 1..65535" <> _ = message(Plan.main(["upload", "a.plan", "--connect", "udpin:127.0.0.1:0"]))
    assert "--name \"\": a name that is not empty" <> _ = message(Plan.main(["import", "a.plan", "--name", ""]))
    # Bad usage: the task's exit status is 2.
    assert %Mix.Error{mix: 2} = assert_raise(Mix.Error, fn -> Plan.run(["export", @example, "x", "o.plan", "--home", "91,0,0"]) end)
  end

  test "a plan that cannot be written is bad usage, said before anything is done", %{tmp_dir: dir} do
    out = Path.join([dir, "missing", "o.plan"])
    assert {:error, %Dolphin.CommandLineError{reason: :usage} = e} = Plan.main(["export", @example, "Survey Area", out])
    assert Exception.message(e) =~ "export #{out}: cannot create it: no such directory #{Path.join(dir, "missing")}\nusage: mix dolphin.plan"
    # Before any vehicle is looked for (there is none on this port: "no vehicle heard" after the --timeout).
    assert {:error, %Dolphin.CommandLineError{reason: :usage} = e} = Plan.main(["download", out, "--connect", "udpin:127.0.0.1:#{Dolphin.Test.GroundStation.free_udp_port()}", "--timeout", "5"])
    assert Exception.message(e) =~ "download #{out}: cannot create it: no such directory"
    assert message(Plan.main(["download", dir, "--connect", "udpin:127.0.0.1:#{Dolphin.Test.GroundStation.free_udp_port()}"])) =~ "download #{dir}: it is a directory, not a file"
  end

  test "the task raises on errors and prints on success", %{tmp_dir: dir} do
    assert_raise Mix.Error, ~r/mix dolphin.plan: no command given/, fn -> Plan.run([]) end
    Mix.shell(Mix.Shell.Process)
    on_exit(fn -> Mix.shell(Mix.Shell.IO) end)
    Plan.run(["export", @example, "Return to base", Path.join(dir, "r.plan")])
    assert_received {:mix_shell, :info, ["wrote " <> _]}
  end

  defp message(result) do
    assert {:error, %Dolphin.CommandLineError{} = e} = result
    Exception.message(e)
  end
end
