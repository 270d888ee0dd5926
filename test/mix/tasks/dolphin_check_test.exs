defmodule Mix.Tasks.Dolphin.CheckTest do
  use ExUnit.Case

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

  test "exit 2 on bad usage" do
    assert {2, _, err} = main(["nope.exs"])
    assert err =~ "no such script: nope.exs"
    assert {2, _, err} = main([Path.join(@dir, "ok.exs"), "--sim", "1", "--fleet", "x.json"])
    assert err =~ "do not go together"
    assert {2, _, _} = main([Path.join(@dir, "ok.exs"), "--bogus"])
    assert {2, _, err} = main([Path.join(@dir, "ok.exs"), "--fleet", Path.join(@dir, "ok.exs")])
    assert err =~ "fleet file"
  end
end
