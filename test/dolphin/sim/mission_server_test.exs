defmodule Dolphin.Sim.MissionServerTest do
  # The vehicle side of the mission protocol, as ArduCopter plays it.
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.MissionServer

  @gcs {255, 190}
  @home %M.MissionItemInt{command: 16, frame: 0, x: 404_442_330, y: -73_752_340, z: 820.0}

  defp ctx(now \\ 0), do: %{now: now, home: @home}
  defp item(seq, command \\ 16, frame \\ 6), do: %M.MissionItemInt{seq: seq, command: command, frame: frame, x: 404_440_000 + seq, y: -73_750_000, z: 20.0, autocontinue: 1}
  defp count(n, type \\ 0), do: %M.MissionCount{target_system: 1, target_component: 1, count: n, mission_type: type}

  defp upload(s, items, type \\ 0) do
    {s, _} = MissionServer.handle(s, count(length(items), type), @gcs, ctx())
    Enum.reduce(items, {s, []}, fn i, {s, _} -> MissionServer.handle(s, %{i | mission_type: type}, @gcs, ctx()) end)
  end

  test "asks for each item with MISSION_REQUEST, keeps items 1.., acks and announces" do
    s = MissionServer.new()
    {s, [{:send, %M.MissionRequest{seq: 0, target_system: 255, target_component: 190}}]} = MissionServer.handle(s, count(3), @gcs, ctx())
    {s, [{:send, %M.MissionRequest{seq: 1}}]} = MissionServer.handle(s, item(0), @gcs, ctx())
    {s, [{:send, %M.MissionRequest{seq: 2}}]} = MissionServer.handle(s, item(1), @gcs, ctx())
    {s, replies} = MissionServer.handle(s, item(2), @gcs, ctx())
    assert [{:send, %M.MissionAck{type: 0}}, {:changed, 0}, {:text, 6, "Flight plan received"}] = replies
    # Item 0 is home: ignored.
    assert Enum.map(MissionServer.items(s), & &1.seq) == [1, 2]
  end

  test "the gives_up fault: the next uploads dropped at their last item with MAV_MISSION_ERROR, nothing stored; then as usual" do
    {s, replies} = upload(MissionServer.new(gives_up: 1), [item(0), item(1), item(2)])
    assert [{:send, %M.MissionAck{type: 1}}] = replies
    assert MissionServer.items(s) == [] and s.upload == nil
    {s, [{:send, %M.MissionAck{type: 0}} | _]} = upload(s, [item(0), item(1), item(2)])
    assert Enum.map(MissionServer.items(s), & &1.seq) == [1, 2]
  end

  test "MISSION_REQUEST_INT when configured so" do
    {_s, [{:send, %M.MissionRequestInt{seq: 0}}]} = MissionServer.handle(MissionServer.new(request_int: true), count(2), @gcs, ctx())
  end

  # As ArduCopter SITL does: the answer is the ack alone; asking again is the
  # timer's business (a re-request per unexpected item would feed a storm on
  # a link that duplicates).
  test "a wrong seq draws INVALID_SEQUENCE and nothing else, and does not count as an item" do
    {s, _} = MissionServer.handle(MissionServer.new(), count(3), @gcs, ctx(0))
    {s, _} = MissionServer.handle(s, item(0), @gcs, ctx(0))
    {s, [{:send, %M.MissionAck{type: 13}}]} = MissionServer.handle(s, item(2), @gcs, ctx(5_000))
    {s, [{:send, %M.MissionAck{type: 13}}]} = MissionServer.handle(s, item(0), @gcs, ctx(7_000))
    # 8 s after the last item it took, not after the wrong ones, it gives up.
    {_s, [{:send, %M.MissionAck{type: 15}} | _]} = MissionServer.timeout(s, 8_001)
  end

  # Seen on ArduCopter SITL 4.7: after MISSION_COUNT, a MISSION_ACK from the
  # ground station (ACCEPTED, as a download ends, or OPERATION_CANCELLED)
  # draws nothing, and the upload goes on to its ACCEPTED.
  test "a ground station's MISSION_ACK during an upload changes nothing" do
    {s, _} = MissionServer.handle(MissionServer.new(), count(3), @gcs, ctx())

    s =
      for type <- [0, 15], reduce: s do
        s ->
          {s, []} = MissionServer.handle(s, %M.MissionAck{type: type, mission_type: 0}, @gcs, ctx())
          s
      end

    {s, [{:send, %M.MissionRequest{seq: 1}}]} = MissionServer.handle(s, item(0), @gcs, ctx())
    {s, [{:send, %M.MissionRequest{seq: 2}}]} = MissionServer.handle(s, item(1), @gcs, ctx())
    {s, [{:send, %M.MissionAck{type: 0}} | _]} = MissionServer.handle(s, item(2), @gcs, ctx())
    assert Enum.map(MissionServer.items(s), & &1.seq) == [1, 2]
  end

  test "while an upload is under way downloads are DENIED; after it, an item is an ERROR" do
    {s, _} = MissionServer.handle(MissionServer.new(), count(2), @gcs, ctx())
    {s, [{:send, %M.MissionAck{type: 14}}]} = MissionServer.handle(s, %M.MissionRequestList{mission_type: 0}, @gcs, ctx())
    {s, [{:send, %M.MissionAck{type: 14}}]} = MissionServer.handle(s, %M.MissionRequestInt{seq: 0, mission_type: 0}, @gcs, ctx())
    {s, _} = MissionServer.handle(s, item(0), @gcs, ctx())
    {s, [{:send, %M.MissionAck{type: 0}} | _]} = MissionServer.handle(s, item(1), @gcs, ctx())
    # The last item again (its ACCEPTED lost, say): no upload is under way.
    {_s, [{:send, %M.MissionAck{type: 1}}]} = MissionServer.handle(s, item(1), @gcs, ctx())
  end

  # As ArduCopter 4.7 SITL does (test/dolphin/sitl/differential_test.exs).
  test "a clear during an upload is accepted and ends it; a cleared mission counts no items until home is written again" do
    {s, _} = MissionServer.handle(MissionServer.new(), count(3), @gcs, ctx())
    {s, _} = MissionServer.handle(s, item(0), @gcs, ctx())
    {s, [{:send, %M.MissionAck{type: 0}}, {:changed, 0}]} = MissionServer.handle(s, %M.MissionClearAll{mission_type: 0}, @gcs, ctx())
    {s, [{:send, %M.MissionAck{type: 1}}]} = MissionServer.handle(s, item(1), @gcs, ctx())
    {s, [{:send, %M.MissionCount{count: 0}}]} = MissionServer.handle(s, %M.MissionRequestList{mission_type: 0}, @gcs, ctx())
    s = MissionServer.home_written(s)
    {_s, [{:send, %M.MissionCount{count: 1}}]} = MissionServer.handle(s, %M.MissionRequestList{mission_type: 0}, @gcs, ctx())
  end

  test "a request past the end draws MISSION_COUNT and INVALID_SEQUENCE" do
    {s, [{:send, %M.MissionCount{count: 1}}, {:send, %M.MissionAck{type: 13}}]} =
      MissionServer.handle(MissionServer.new(), %M.MissionRequestInt{seq: 40, mission_type: 0}, @gcs, ctx())

    assert s == MissionServer.new()
  end

  test "silence: asked again every second, 8 times, then OPERATION_CANCELLED" do
    {s, _} = MissionServer.handle(MissionServer.new(), count(3), @gcs, ctx(0))
    assert MissionServer.deadline(s) == 1_000
    {s, []} = MissionServer.timeout(s, 500)

    s =
      Enum.reduce(1..8, s, fn k, s ->
        {s, [{:send, %M.MissionRequest{seq: 0}}]} = MissionServer.timeout(s, k * 1_000)
        s
      end)

    {s, [{:send, %M.MissionAck{type: 15}}, {:text, 3, "Mission upload timeout"}]} = MissionServer.timeout(s, 9_000)
    assert MissionServer.deadline(s) == nil
  end

  test "given real time, the upload also waits 2 s of it: a pause of the host that the sped-up clock counts as 8 s does not end it" do
    {s, _} = MissionServer.handle(MissionServer.new(), count(3), @gcs, Map.put(ctx(0), :real, 100))
    {s, [_]} = MissionServer.handle(s, item(0), @gcs, Map.put(ctx(200), :real, 110))

    # 9 s of vehicle time since the item, in 1.5 s of real time: asked again, not cancelled.
    {s, [{:send, %M.MissionRequest{seq: 1}}]} = MissionServer.timeout(s, 9_200, 1_610)
    # Once 2 s of real time have passed as well, cancelled.
    {s, [{:send, %M.MissionAck{type: 15}}, {:text, 3, "Mission upload timeout"}]} = MissionServer.timeout(s, 9_300, 2_111)
    assert MissionServer.deadline(s) == nil

    # Real time alone does not end it before the vehicle's 8 s.
    {s, _} = MissionServer.handle(MissionServer.new(), count(3), @gcs, Map.put(ctx(0), :real, 0))
    {_, [{:send, %M.MissionRequest{seq: 0}}]} = MissionServer.timeout(s, 7_000, 60_000)

    # Past the 8 s, within the 2 s of real time: its timer is the next re-request, not the 8 s already past.
    {s, _} = MissionServer.handle(MissionServer.new(), count(3), @gcs, Map.put(ctx(0), :real, 0))
    {s, [{:send, %M.MissionRequest{seq: 0}}]} = MissionServer.timeout(s, 9_000, 1_000)
    assert MissionServer.deadline(s) == 10_000

    # Real time on one side only: the vehicle's 8 s decide.
    {s, _} = MissionServer.handle(MissionServer.new(), count(3), @gcs, ctx(0))
    {_, [{:send, %M.MissionAck{type: 15}}, _]} = MissionServer.timeout(s, 9_000, 1)
  end

  test "too many items, an unknown command, a second uploader" do
    {_, [{:send, %M.MissionAck{type: 4}}, {:text, 3, "Only 650 items are supported"}]} = MissionServer.handle(MissionServer.new(), count(60_000), @gcs, ctx())

    {s, _} = MissionServer.handle(MissionServer.new(), count(2), @gcs, ctx())
    {s, _} = MissionServer.handle(s, item(0), @gcs, ctx())
    {_, [{:send, %M.MissionAck{type: 3}} | _]} = MissionServer.handle(s, item(1, 31_999), @gcs, ctx())

    {_, [{:send, %M.MissionAck{type: 14, target_system: 254}}]} = MissionServer.handle(s, count(2), {254, 190}, ctx())
  end

  test "download: item 0 is home, frames come back normalised; MISSION_REQUEST answered with MISSION_ITEM" do
    {s, _} = upload(MissionServer.new(), [item(0), item(1, 22, 6), item(2, 16, 5)])
    {s, [{:send, %M.MissionCount{count: 3}}]} = MissionServer.handle(s, %M.MissionRequestList{mission_type: 0}, @gcs, ctx())
    {s, [{:send, %M.MissionItemInt{seq: 0, frame: 0, x: 404_442_330, z: 820.0}}]} = MissionServer.handle(s, %M.MissionRequestInt{seq: 0}, @gcs, ctx())
    {s, [{:send, %M.MissionItemInt{seq: 1, command: 22, frame: 3}}]} = MissionServer.handle(s, %M.MissionRequestInt{seq: 1}, @gcs, ctx())
    {_s, [{:send, %M.MissionItem{seq: 2, frame: 0, x: x}}]} = MissionServer.handle(s, %M.MissionRequest{seq: 2}, @gcs, ctx())
    assert_in_delta x, 40.444, 0.001
  end

  test "the float MISSION_ITEM is accepted with ArduPilot's complaint" do
    {s, _} = MissionServer.handle(MissionServer.new(), count(2), @gcs, ctx())
    {s, _} = MissionServer.handle(s, item(0), @gcs, ctx())
    float = %M.MissionItem{seq: 1, command: 16, frame: 3, x: 40.5, y: -7.25, z: 30.0}
    {s, [{:text, 4, "GCS should send MISSION_ITEM_INT"}, {:send, %M.MissionAck{type: 0}} | _]} = MissionServer.handle(s, float, @gcs, ctx())
    assert [%M.MissionItemInt{x: 405_000_000, y: -72_500_000}] = MissionServer.items(s)
  end

  test "fence and rally lists are kept whole; clear empties a list" do
    {s, _} = upload(MissionServer.new(), [item(0, 5003, 5), item(1, 5003, 5)], 1)
    assert length(MissionServer.items(s, 1)) == 2
    {s, [{:send, %M.MissionAck{type: 0, mission_type: 1}}, {:changed, 1}]} = MissionServer.handle(s, %M.MissionClearAll{mission_type: 1}, @gcs, ctx())
    assert MissionServer.items(s, 1) == []
  end
end
