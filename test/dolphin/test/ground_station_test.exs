defmodule Dolphin.Test.GroundStationTest do
  # The clean-up between simulated fleets (test/support/ground_station.ex):
  # what the vehicles sent before they stopped is read before they are
  # forgotten, or it brings one back as a ghost at an address nobody answers
  # from (and the next vehicle 1 would be taken for another path of it).
  # Its own Dolphin.Instance: async.
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.Frame
  alias Dolphin.MAVLink.Ardupilotmega.Heartbeat
  alias Dolphin.Test.GroundStation
  alias Dolphin.Vehicles

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  test "a heartbeat still unread in the link when the vehicles are forgotten does not bring its vehicle back" do
    port = GroundStation.open()
    # This test's instance has one link: the one just opened.
    [link] = Registry.select(Dolphin.Instance.names().registry, [{{{:link, :_}, :"$1", :_}, [], [:"$1"]}])

    # The link does not read for a while: a copter's last heartbeat waits in its socket.
    :ok = :sys.suspend(link)
    {:ok, vehicle} = :gen_udp.open(0, ip: {127, 0, 0, 1})
    :ok = :gen_udp.send(vehicle, {127, 0, 0, 1}, port, Frame.encode(%Heartbeat{type: 2, autopilot: 3}, sysid: 7, compid: 1, seq: 0))
    :gen_udp.close(vehicle)
    resumer = Task.async(fn -> Process.sleep(200) && :sys.resume(link) end)

    GroundStation.forget_vehicles()
    Task.await(resumer)

    # Read and forgotten: whatever the link does next, it has nothing more of vehicle 7.
    _ = :sys.get_state(link)
    assert Vehicles.list() == []
  end
end
