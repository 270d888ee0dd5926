# Vehicles replayed from another OS process (bench/replay_feed.py): each
# vehicle's telemetry encoded here beforehand, then sent by the script from
# the vehicle's own UDP socket on 127.0.0.1 at a fixed rate. No simulation
# runs there, so a machine of two cores can feed thousands of vehicles.
# Used by bench/cluster.exs and bench/intake.exs (FEED=replay).
#
# Each vehicle is a map: `port` (the link it sends to), `sysid`, `index`
# (0-based over the feed; its autopilot's unique id is index + 1).
# `fps` frames a second a vehicle: a HEARTBEAT and a SYS_STATUS each second,
# the rest GLOBAL_POSITION_INT, a new position each time (2 m further north).

defmodule Bench.ReplayFeed do
  @moduledoc false
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.Frame

  import Bitwise

  @cycle 256

  @doc "Starts the feed of `vehicles`, each at `fps` frames a second: %{port, os_pid} once every socket is open."
  def start(vehicles, fps) do
    path = Path.join(System.tmp_dir!(), "dolphin_replay_feed_#{System.unique_integer([:positive])}.bin")
    File.write!(path, Enum.map(vehicles, &vehicle(&1, fps)))
    script = Path.expand("replay_feed.py", __DIR__)
    port = Port.open({:spawn_executable, System.find_executable("python3")}, [:binary, :exit_status, {:line, 256}, args: [script, path, "#{fps}"]])

    try do
      Bench.OSProcess.await_line(port, ~r/^feeding/, 120_000)
    after
      File.rm(path)
    end

    {:os_pid, os_pid} = Port.info(port, :os_pid)
    %{port: port, os_pid: os_pid}
  end

  @doc "Switches vehicle `index` to its low-battery cycle."
  def low_battery(%{port: port}, index), do: true = Port.command(port, "low #{index}\n")

  @doc "Stops the feed: the number of frames it sent."
  def stop(%{port: port}) do
    true = Port.command(port, "quit\n")
    [sent] = Regex.run(~r/^\d+$/, Bench.OSProcess.await_line(port, ~r/^\d+$/, 30_000))
    receive do: ({^port, {:exit_status, _}} -> :ok), after: (10_000 -> Port.close(port))
    String.to_integer(sent)
  end

  # The script's file entry of one vehicle: its link's port, then two cycles
  # of @cycle frames, the second with the battery low.
  defp vehicle(%{port: port} = v, fps) do
    frames = cycle(v, fps, 80) ++ cycle(v, fps, 20)
    [<<port::little-16, @cycle::little-16>> | Enum.map(frames, &<<byte_size(&1)::little-16, &1::binary>>)]
  end

  defp cycle(%{sysid: sysid} = v, fps, battery),
    do: for(i <- 0..(@cycle - 1), do: Frame.encode(message(i, v, fps, battery), sysid: sysid, compid: 1, seq: i))

  # A HEARTBEAT first, then each second `fps - 2` positions, a SYS_STATUS
  # and a HEARTBEAT; its unique id (AUTOPILOT_VERSION, which the feed
  # cannot send when asked) in place of every 16th frame from the second
  # on: a station that has yet to tell the path is this vehicle's drops
  # what it hears on it.
  defp message(0, _v, _fps, _battery), do: heartbeat()
  defp message(i, %{index: index}, _fps, _battery) when rem(i, 16) == 1, do: %M.AutopilotVersion{capabilities: 0xFFFF, flight_sw_version: 0x04060000, uid: index + 1, vendor_id: 0x1209, product_id: 0x5740}

  defp message(i, %{index: index}, fps, battery) do
    case rem(i - 2, fps) do
      p when p == fps - 1 -> heartbeat()
      p when p == fps - 2 -> %M.SysStatus{voltage_battery: 12_100, current_battery: 2_800, battery_remaining: battery, load: 200}
      _ -> %M.GlobalPositionInt{time_boot_ms: div(i * 1000, fps), lat: 411_780_000 + rem(index, 1000) * 1_000 + i * 180, lon: -85_960_000 + div(index, 1000) * 10_000, alt: 132_000, relative_alt: 30_000, vx: 500, hdg: 0}
    end
  end

  # A copter flying in GUIDED, armed.
  defp heartbeat, do: %M.Heartbeat{type: 2, autopilot: 3, base_mode: 1 ||| 8 ||| 16 ||| 128, custom_mode: 4, system_status: 4, mavlink_version: 3}
end
