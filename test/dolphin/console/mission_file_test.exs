defmodule Dolphin.Console.MissionFileTest do
  # Evaluates files; one test checks that no event was emitted: not async.
  use ExUnit.Case, async: false

  alias Dolphin.Console.MissionFile

  doctest Dolphin.Console.MissionFileError

  @moduletag :tmp_dir
  @fixtures Path.expand("../../fixtures/console", __DIR__)

  test "a file of missions: variables, lists and bare blocks" do
    assert {:ok, found, []} = MissionFile.read(Path.join(@fixtures, "missions.exs"))

    assert Enum.map(found, &{&1.var, &1.mission.name}) == [
             {"inspection", "Inspection"},
             {"tour[0]", "Leg 30-0"},
             {"tour[1]", "Leg 0-30"},
             {nil, "Hop"}
           ]

    assert [%{line: 13}] = Enum.filter(found, &(&1.var == nil))
  end

  test "a script: its missions are found and nothing of it runs" do
    Dolphin.Events.subscribe()
    path = Path.join(@fixtures, "script_with_missions.exs")
    assert {:ok, found, notes} = MissionFile.read(path)
    assert Enum.map(found, &{&1.var, &1.mission.name}) == [{"later", "Later"}, {"survey", "Survey"}]

    assert [pick, message, broken, execute] = notes
    assert pick =~ "script_with_missions.exs:13: skipped (it calls pick)"
    assert message =~ ":14: skipped (not a definition)"
    assert broken =~ ":15: not evaluated: key :nothing not found"
    assert execute =~ ":21: skipped (not a definition)"

    refute_received {:dolphin, :events, %{event: :message}}
    refute_received {:dolphin, :events, %{event: :picked}}
    refute_received {:dolphin, :events, %{event: :pick_failed}}
  end

  test "files that are not scripts or missions, missing files, syntax errors", %{tmp_dir: dir} do
    other = Path.join(dir, "other.exs")
    File.write!(other, "IO.puts(:hello)\n")
    why = message(MissionFile.read(other))
    assert why =~ "neither a Dolphin script"

    why = message(MissionFile.read(Path.join(dir, "nope.exs")))
    assert why =~ "cannot read: no such file"

    bad = Path.join(dir, "bad.exs")
    File.write!(bad, "use Dolphin.Script\nm = mission \"x\" do\n")
    why = message(MissionFile.read(bad))
    assert why =~ ~r/bad.exs:\d+: syntax error/
  end

  test "the evaluation is bounded in time", %{tmp_dir: dir} do
    slow = Path.join(dir, "slow.exs")
    File.write!(slow, "use Dolphin.Script\nx = Process.sleep(:infinity)\n")
    why = message(MissionFile.read(slow, timeout: 200))
    assert why =~ "took longer than"
  end

  test "picking a mission by name or by variable" do
    {:ok, found, _} = MissionFile.read(Path.join(@fixtures, "missions.exs"))
    assert {:ok, %{var: "inspection"}} = MissionFile.pick(found, "Inspection")
    assert {:ok, %{mission: %{name: "Inspection"}}} = MissionFile.pick(found, "inspection")
    assert {:ok, %{mission: %{name: "Hop"}}} = MissionFile.pick(found, "Hop")
    why = message(MissionFile.pick(found, "Nope"))
    assert why =~ ~s{no mission "Nope"; the file defines: "Inspection" (inspection), "Leg 30-0" (tour[0])}

    twice = found ++ [%{var: "other", mission: %{hd(found).mission | commands: []}, line: nil}]
    why = message(MissionFile.pick(twice, "Inspection"))
    assert why =~ "2 different missions answer to \"Inspection\""
    assert MissionFile.describe([]) == "the file defines no mission"
  end

  test "acting words are found anywhere in a statement" do
    assert MissionFile.acting(quote(do: x = execute(%{v => t}))) == :execute
    assert MissionFile.acting(quote(do: y = if(true, do: pick(count: 1)))) == :pick
    assert MissionFile.acting(quote(do: z = mission("m", do: delay(1)))) == nil
  end

  defp message(result) do
    assert {:error, %Dolphin.Console.MissionFileError{} = e} = result
    Exception.message(e)
  end
end
