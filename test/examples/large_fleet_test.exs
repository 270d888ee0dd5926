defmodule Dolphin.Examples.LargeFleetTest do
  # examples/large_fleet.exs: checked as its header says to run it, a
  # thousand simulated vehicles over four networks (the pre-flight check, an
  # OS process); flown as written but for its count, on twelve simulated
  # vehicles over three networks of five (a thousand fly in about a minute
  # and a half on two cores, docs/benchmarks.md: too long for the suite).
  use ExUnit.Case, async: true

  alias Dolphin.Sim.Local

  @moduletag timeout: 300_000

  @example Path.expand("../../examples/large_fleet.exs", __DIR__)

  test "the pre-flight check of a thousand: every vehicle's mission, the networks' vehicles named SYSID@simK, no conflict" do
    {out, status} = System.cmd("mix", ["dolphin.check", @example, "--sim", "1000"], stderr_to_stdout: true, env: [{"MIX_ENV", "test"}])
    assert status == 0, out
    assert out =~ ~r/large_fleet\.exs: 0 error\(s\), 0 warning\(s\), 0 note\(s\); 1000 mission\(s\) checked/
    assert out =~ ~s(mission "Hop" on vehicle 254: 80 m)
    assert out =~ ~s(mission "Hop" on vehicle 238@sim4: 80 m)
    refute out =~ "239@sim4"
  end

  test "flown on twelve vehicles over three networks: each its own hop, none held, all landed" do
    Dolphin.Test.Instance.start!()
    Dolphin.Clock.set_speedup(10)
    Dolphin.Events.subscribe()
    {:ok, sim} = Local.start(12, network_size: 5)
    assert sim.sysids == [1, 2, 3, 4, 5, "1@sim2", "2@sim2", "3@sim2", "4@sim2", "5@sim2", "1@sim3", "2@sim3"]

    source = String.replace(File.read!(@example), "count = 1000\n", "count = 12\n")
    assert source != File.read!(@example)
    {:ok, script} = Dolphin.Script.compile_string(source, @example)
    assert {:ok, %{result: :done}} = Dolphin.Script.run(script)

    events = Dolphin.Test.Wait.received_events()
    assert [%{text: "12 vehicles flew their hops"}] = for(%{event: :message} = e <- events, do: e)
    flown = for %{event: :task_finished, kind: :mission, result: :done, vehicle: v} <- events, do: v
    assert Enum.sort(flown) == Enum.sort(sim.sysids)
    assert for(%{event: :separation_hold} = e <- events, do: e) == []

    # Each took its photo at 40 m over its own spot, and landed there.
    for key <- [3, {2, 5}, {3, 2}] do
      {:ok, %{photos: 1, landed: :on_ground, mission: items, home: home}} = Dolphin.Sim.info(key)
      assert [_climb] = for(%{command: 16, z: z} <- items, round(z - home.alt) == 40, do: z), "vehicle #{inspect(key)}: #{inspect(items)}"
    end

    :ok = Local.stop(sim)
  end
end
