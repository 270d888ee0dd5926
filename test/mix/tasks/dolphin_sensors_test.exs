defmodule Mix.Tasks.Dolphin.SensorsTest do
  # `mix dolphin.sensors` in its own OS process, as a user runs it beside
  # ArduPilot SITL: this test plays the autopilot on its second telemetry
  # port (a UDP socket on 127.0.0.1) and reads what the sidecar says back.
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.{Frame, Parser}
  alias Dolphin.Test.{GroundStation, MixCommand}

  @moduletag :tmp_dir
  @moduletag timeout: 300_000

  # A fire at the autopilot's position.
  @at {40.4470, -7.3740}

  defp world(dir) do
    path = Path.join(dir, "world.json")
    {lat, lon} = @at
    File.write!(path, ~s({"fires": [{"lat": #{lat}, "lon": #{lon}, "radius_m": 40, "intensity": 0.9}]}))
    path
  end

  # What the sidecar sent, decoded, until `fun` holds for one (bounded).
  defp receive_until(socket, fun, seen \\ []) do
    case :gen_udp.recv(socket, 0, 30_000) do
      {:ok, {_ip, _port, data}} ->
        {frames, _} = Parser.feed(Parser.new(), data)
        seen = seen ++ frames
        if Enum.any?(frames, fun), do: seen, else: receive_until(socket, fun, seen)

      {:error, :timeout} ->
        flunk("nothing as expected from the sidecar; it said: #{inspect(Enum.map(seen, & &1.message))}\n#{MixCommand.output()}")
    end
  end

  test "it asks the autopilot for its position and sends back its smoke readings as the vehicle's component 191", %{tmp_dir: dir} do
    port = GroundStation.free_udp_port()
    command = MixCommand.start(["dolphin.sensors", "--world", world(dir), "--connect", "udpin:127.0.0.1:#{port}", "--rate", "10", "--noise", "0", "--for", "6"])
    MixCommand.wait_for(command, ~r/sensor sidecar on udpin:127.0.0.1:#{port}: smoke for every vehicle heard/)

    {:ok, autopilot} = :gen_udp.open(0, [:binary, ip: {127, 0, 0, 1}, active: false])
    say = fn message, seq -> :ok = :gen_udp.send(autopilot, {127, 0, 0, 1}, port, Frame.encode(message, sysid: 7, compid: 1, seq: seq)) end
    say.(%M.Heartbeat{type: 2, autopilot: 3, base_mode: 0, custom_mode: 0, system_status: 4, mavlink_version: 3}, 0)

    # Asked: GLOBAL_POSITION_INT (33) every 100 ms, by SET_MESSAGE_INTERVAL from the vehicle's companion.
    asked = receive_until(autopilot, &match?(%M.CommandLong{command: 511}, &1.message))
    assert %Frame{sysid: 7, compid: 191, message: %M.CommandLong{target_system: 7, param1: 33.0, param2: 100_000.0}} = Enum.find(asked, &match?(%M.CommandLong{}, &1.message))

    {lat, lon} = @at

    for i <- 1..30 do
      say.(%M.GlobalPositionInt{time_boot_ms: i * 100, lat: round(lat * 1.0e7), lon: round(lon * 1.0e7), alt: 870_000, relative_alt: 50_000}, i)
    end

    frames = receive_until(autopilot, &match?(%M.NamedValueFloat{name: "SMOKE"}, &1.message))
    assert %Frame{sysid: 7, compid: 191, message: %M.NamedValueFloat{value: value}} = Enum.find(frames, &match?(%M.NamedValueFloat{}, &1.message))
    # Over the fire's centre, no noise: its intensity.
    assert_in_delta value, 0.9, 1.0e-6
    assert Enum.any?(frames, &match?(%Frame{compid: 191, message: %M.Heartbeat{type: 18}}, &1))

    output = MixCommand.wait_exit(command, 0)
    assert output =~ ~r/vehicle 7: \d+ readings sent/
    :gen_udp.close(autopilot)
  end

  test "a world file that is wrong is refused with its line (status 1); a sensor no model has is bad usage (status 2)", %{tmp_dir: dir} do
    bad = Path.join(dir, "bad.json")
    File.write!(bad, ~s({"fires": [\n  {"lat": 40.4, "lon": -7.3, "radius_m": 40}\n]}))

    assert [{1, missing}, {2, sensor}, {2, none}] =
             MixCommand.run_all([
               ["dolphin.sensors", "--world", bad, "--for", "1"],
               ["dolphin.sensors", "--world", world(dir), "--sensors", "smoke,heat", "--for", "1"],
               ["dolphin.sensors", "--for", "1"]
             ])

    assert missing =~ "mix dolphin.sensors: --world: #{bad}: line 2: fires[0]: intensity is missing; a fire takes lat, lon, radius_m, intensity"
    assert sensor =~ ~s(mix dolphin.sensors: --sensors smoke,heat: no simulated sensor "heat": the simulator's sensors are range, smoke, water_temp)
    assert none =~ "mix dolphin.sensors: --world FILE is required"
  end
end
