# A tour of the ground station with one vehicle made by pymavlink (the
# reference MAVLink implementation; scripts/pymavlink_vehicle.py) over UDP on
# 127.0.0.1: discovery, telemetry, a mode change, a mission upload, each seen
# from both sides.
#
#   mix run examples/ground_station_tour.exs
#
# (`make run` flies examples/two_vehicles.exs, not this; the scenario tests run
# this tour exactly so and check what it prints.) It needs the project's venv
# with pymavlink, which scripts/bootstrap creates.
alias Dolphin.{Link, Vehicles}
alias Dolphin.Link.Connection
alias Dolphin.MAVLink.Ardupilotmega, as: M

python = Path.expand("../.venv/bin/python", __DIR__)
vehicle_script = Path.expand("../scripts/pymavlink_vehicle.py", __DIR__)
File.exists?(python) || Mix.raise("#{python} is missing: run scripts/bootstrap (make run does)")

{:ok, _} = Link.connect("udpin:127.0.0.1:0", name: "tour")
port = Connection.port("tour")
IO.puts("== Ground station listening on udpin:127.0.0.1:#{port}; starting a pymavlink vehicle (system 1)")
Vehicles.subscribe(:all)
vehicle = Port.open({:spawn_executable, python}, [:binary, {:line, 65_536}, :exit_status, args: [vehicle_script, "#{port}", "1", "4"]])

receive do
  {:dolphin, :vehicles, {:vehicle_discovered, 1}} -> IO.puts("  discovered vehicle 1 from its HEARTBEAT")
after
  5_000 -> Mix.raise("the vehicle was not heard")
end

# Telemetry arrives once the ground station has asked for it.
Enum.find_value(1..100, fn _ ->
  with {:ok, %{position: %{}} = s} <- Vehicles.state(1), do: s, else: (_ -> Process.sleep(20) && nil)
end)

{:ok, s} = Vehicles.state(1)
IO.puts("  state: mode #{inspect(s.mode)}, armed #{s.armed}, battery #{round(s.battery * 100)} %, at #{s.position.lat}, #{s.position.lon}, #{s.position.relative_alt} m up")

IO.puts("\n== Commands (COMMAND_LONG, acknowledged)")
IO.puts("  set mode :brake -> #{inspect(Vehicles.set_mode(1, :brake))}")
IO.puts("  set mode :warp  -> #{inspect(Vehicles.set_mode(1, :warp) |> elem(1) |> Exception.message())}")

IO.puts("\n== Mission upload (the vehicle asks for each item, as ArduCopter does)")
{:ok, takeoff} = M.enum_value(:mav_cmd, :mav_cmd_nav_takeoff)
{:ok, waypoint} = M.enum_value(:mav_cmd, :mav_cmd_nav_waypoint)
{:ok, rtl} = M.enum_value(:mav_cmd, :mav_cmd_nav_return_to_launch)

mission =
  [%M.MissionItemInt{frame: 0, command: waypoint, x: 411_780_000, y: -85_960_000}] ++
    [%M.MissionItemInt{frame: 6, command: takeoff, z: 20.0}] ++
    for(i <- 1..3, do: %M.MissionItemInt{frame: 6, command: waypoint, x: 411_780_000 + i * 5_000, y: -85_960_000, z: 20.0}) ++
    [%M.MissionItemInt{frame: 6, command: rtl}]

:ok = Vehicles.upload_mission(1, mission, progress_to: self())
for _ <- mission, do: receive(do: ({:mission_progress, :upload, done, total} -> IO.write("\r  sent #{done}/#{total}")))
IO.puts("\n  accepted by the vehicle (MISSION_ACK 0)")

# What the vehicle itself says it received.
lines =
  Stream.repeatedly(fn ->
    receive do
      {^vehicle, {:data, {:eol, line}}} -> line
      {^vehicle, {:exit_status, _}} -> nil
    after
      6_000 -> nil
    end
  end)
  |> Enum.take_while(&(&1 != nil and not String.contains?(&1, "done")))
  |> Enum.map(&elem(Dolphin.MAVLink.JSON.decode(&1), 1))

for %{"command" => c, "param1" => p1} <- lines, do: IO.puts("  vehicle got COMMAND_LONG #{c} (param1 #{p1})")

for %{"mission" => items} <- lines do
  IO.puts("  vehicle holds #{length(items)} items:")
  for i <- items, do: IO.puts("    ##{i["seq"]} #{inspect(elem(M.enum_name(:mav_cmd, i["command"]), 1))} frame #{i["frame"]} x #{i["x"]} y #{i["y"]} z #{i["z"]}")
end
