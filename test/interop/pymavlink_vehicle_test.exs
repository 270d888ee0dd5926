defmodule Dolphin.Interop.PymavlinkVehicleTest do
  # The ground station against a vehicle made with pymavlink (the reference
  # implementation) over UDP on 127.0.0.1: discovery, telemetry, a command,
  # a mission upload, each checked from both sides.
  use ExUnit.Case, async: true

  # A Dolphin.Instance of its own: its vehicles, links and clock are no other test's.
  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.Test.Wait

  @moduletag :interop

  alias Dolphin.{Link, Vehicles}
  alias Dolphin.Link.Connection
  alias Dolphin.MAVLink.{JSON}
  alias Dolphin.MAVLink.Ardupilotmega, as: M

  @script Path.expand("../../scripts/pymavlink_vehicle.py", __DIR__)
  @sysid 61

  @tag timeout: 60_000
  test "a pymavlink vehicle is discovered, reports telemetry, takes a command and a mission" do
    python = Dolphin.Test.Pymavlink.python()
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: "pymavlink-vehicle")

    Dolphin.Test.Instance.on_exit(fn ->
      DynamicSupervisor.terminate_child(Dolphin.Instance.names().links, link)
      Vehicles.forget(@sysid)
    end)

    port = Connection.port("pymavlink-vehicle")
    vehicle = Port.open({:spawn_executable, python}, [:binary, :exit_status, {:line, 65_536}, args: [@script, "#{port}", "#{@sysid}", "4"]])

    Wait.until(
      fn -> match?({:ok, %{battery: 0.77, mode: :guided, armed: true, position: %{lat: 41.178}}}, Vehicles.state(@sysid)) end,
      250,
      fn -> inspect(Vehicles.state(@sysid)) end
    )

    assert {:ok, :accepted} = Vehicles.set_mode(@sysid, :brake)

    mission =
      for i <- 0..4 do
        %M.MissionItemInt{frame: 6, command: 16, autocontinue: 1, x: 411_780_000 + i, y: -85_960_000 - i, z: 10.0 + i}
      end

    assert :ok = Vehicles.upload_mission(@sysid, mission)

    lines = collect(vehicle, [])
    assert %{"command" => 176, "param1" => 1.0, "confirmation" => 0} in lines
    [%{"mission" => items}] = Enum.filter(lines, &Map.has_key?(&1, "mission"))

    assert items ==
             for(i <- 0..4, do: %{"seq" => i, "command" => 16, "frame" => 6, "x" => 411_780_000 + i, "y" => -85_960_000 - i, "z" => 10.0 + i})
  end

  # What the vehicle printed, until it says it is done (after its 4 s).
  defp collect(port, acc) do
    receive do
      {^port, {:data, {:eol, line}}} ->
        {:ok, obj} = JSON.decode(line)
        if obj["done"], do: Enum.reverse(acc), else: collect(port, [obj | acc])

      {^port, {:exit_status, status}} ->
        flunk("the pymavlink vehicle exited with status #{status} before it was done")
    after
      15_000 -> flunk("the pymavlink vehicle said nothing for 15 s")
    end
  end

end
