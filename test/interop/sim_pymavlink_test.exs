defmodule Dolphin.Interop.SimPymavlinkTest do
  # The simulator flown by an outside ground station made with pymavlink (the
  # reference implementation): discover, request streams, upload a mission, GUIDED +
  # arm + MISSION_START, watch it complete and land at home. Its own Dolphin.Instance
  # (its vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  @moduletag :interop

  alias Dolphin.{Clock, Sim}
  alias Dolphin.MAVLink.JSON

  @script Path.expand("../../scripts/pymavlink_gcs.py", __DIR__)
  @speedup 20

  @tag timeout: 300_000
  test "pymavlink as the ground station flies a simulated copter through a mission" do
    python = Dolphin.Test.Pymavlink.python()
    port = Dolphin.Test.GroundStation.free_udp_port()

    Dolphin.Test.Instance.on_exit(fn ->
      Sim.stop()
      Clock.set_speedup(1)
    end)

    gcs = Port.open({:spawn_executable, python}, [:binary, :exit_status, {:line, 65_536}, args: [@script, "#{port}", "9", "#{@speedup}"]])
    assert %{"ready" => true} = next(gcs)
    {:ok, [9]} = Sim.start(sysids: [9], gcs: port, speedup: @speedup, ekf_ready_ms: 10_000)

    assert %{"heartbeat" => %{"sysid" => 9, "type" => 2, "autopilot" => 3}} = next(gcs)
    # The script waits up to 60 s of real time for the home (its commands
    # asked again for 25 s more): a slow Python reader on a loaded machine
    # works through the telemetry before it reaches the answer.
    assert %{"home" => [_lat, _lon, 820.0]} = next(gcs, 100_000)
    # ArduCopter asks for items with MISSION_REQUEST, and so does the simulator.
    assert %{"uploaded" => 4, "requests" => ["MISSION_REQUEST"]} = next(gcs)

    summary = next(gcs, 100_000)
    assert summary["done"] == true, inspect(summary)
    # In order, the last one included (on a busy machine this slow reader may miss a datagram).
    assert List.last(summary["reached"]) == 3 and summary["reached"] == Enum.sort(summary["reached"]) and summary["reached"] -- [1, 2, 3] == []
    assert "AUTO" in summary["modes"]
    assert "Mission: 3 RTL" in summary["texts"] and "Disarming motors" in summary["texts"]
    assert summary["distance_from_home"] < 3
  end

  defp next(port, timeout \\ 30_000) do
    receive do
      {^port, {:data, {:eol, line}}} ->
        {:ok, obj} = JSON.decode(line)
        obj

      {^port, {:exit_status, status}} ->
        flunk("the pymavlink ground station exited with status #{status}")
    after
      timeout -> flunk("the pymavlink ground station said nothing for #{timeout} ms")
    end
  end
end
