# The ground station's mission upload and telemetry intake over loopback.
#
#   1. Upload time of a 100-item and a 700-item mission to a scripted
#      ArduCopter-like vehicle (test/support/scripted_vehicle.ex: ArduCopter's
#      mission protocol rules, Dolphin.Sim.MissionServer), at 0 % and 20 %
#      loss each way, in real time. An upload whose final MISSION_ACK was
#      lost ends :unconfirmed (the vehicle holds the mission: checked here).
#   2. CPU of the ground station for 100 vehicles, each sending ArduPilot-like
#      telemetry (GLOBAL_POSITION_INT, ATTITUDE, VFR_HUD, SYS_STATUS at 10 Hz,
#      HEARTBEAT at 1 Hz) from its own UDP socket, made by a separate OS process
#      (bench/telemetry_sender.py, pymavlink), so the VM's CPU time is the
#      ground station's own.
#
#   make bench        (or: mix run bench/mission_upload.exs)
Code.require_file("../test/support/scripted_vehicle.ex", __DIR__)

alias Dolphin.{Clock, Link, Vehicles}
alias Dolphin.Link.Connection
alias Dolphin.MAVLink.Ardupilotmega, as: M
alias Dolphin.Test.ScriptedVehicle

items = fn n ->
  for i <- 0..(n - 1), do: %M.MissionItemInt{frame: 6, command: 16, autocontinue: 1, x: 411_780_000 + i, y: -85_960_000, z: 20.0}
end

{:ok, _} = Link.connect("udpin:127.0.0.1:0", name: "bench")
port = Connection.port("bench")

IO.puts("mission upload over loopback (#{System.schedulers_online()} schedulers, OTP #{System.otp_release()})")

for {loss, speedup} <- [{0.0, 1}, {0.2, 1}], n <- [100, 700] do
  Clock.set_speedup(speedup)
  sysid = if loss == 0.0, do: 100 + div(n, 100), else: 120 + div(n, 100)
  {:ok, vehicle} = ScriptedVehicle.start_link(port: port, sysid: sysid, speedup: speedup, loss: loss, seed: n)
  Enum.find_value(1..200, fn _ -> Vehicles.whereis(sysid) || (Process.sleep(20) && nil) end)

  runs =
    for _ <- 1..3 do
      {us, result} = :timer.tc(fn -> Vehicles.upload_mission(sysid, items.(n)) end)
      # Unconfirmed (the final ACK lost): what the vehicle holds says.
      held? = length(ScriptedVehicle.mission(vehicle)) == n
      {us, if(match?({:error, %Dolphin.MissionError{result: :unconfirmed}}, result) and held?, do: :unconfirmed, else: result)}
    end

  ok = Enum.count(runs, &(elem(&1, 1) in [:ok, :unconfirmed]))
  unconfirmed = Enum.count(runs, &(elem(&1, 1) == :unconfirmed))
  {best, _} = Enum.min_by(runs, &elem(&1, 0))
  median = runs |> Enum.map(&elem(&1, 0)) |> Enum.sort() |> Enum.at(1)

  failures = for {_, {:error, e}} <- runs, do: Exception.message(e)

  IO.puts(
    "  #{String.pad_leading("#{n}", 3)} items, #{round(loss * 100)} % loss: best #{Float.round(best / 1000, 1)} ms, median #{Float.round(median / 1000, 1)} ms wall" <>
      ", #{ok}/3 uploaded" <> if(unconfirmed > 0, do: " (#{unconfirmed} with the final ACK lost)", else: "") <> Enum.map_join(failures, "", &"\n      failed: #{&1}")
  )

  GenServer.stop(vehicle)
end

Clock.set_speedup(1)

# 2. Telemetry intake.
Code.ensure_loaded(Dolphin.Link.Connection)
vehicles = 100
seconds = 10
python = Path.expand("../.venv/bin/python", __DIR__)
sender = Path.expand("telemetry_sender.py", __DIR__)
{:ok, _} = Link.connect("udpin:127.0.0.1:0", name: "bench-telemetry")
tport = Connection.port("bench-telemetry")

task = Task.async(fn -> System.cmd(python, [sender, "#{tport}", "#{vehicles}", "10", "#{seconds}"]) end)
# Let the vehicles be discovered and the telemetry flow before measuring.
Process.sleep(2_000)
{cpu0, _} = :erlang.statistics(:runtime)
{wall0, _} = :erlang.statistics(:wall_clock)
stats0 = Connection.info("bench-telemetry").stats.frames
Process.sleep(6_000)
{cpu1, _} = :erlang.statistics(:runtime)
{wall1, _} = :erlang.statistics(:wall_clock)
stats1 = Connection.info("bench-telemetry").stats.frames
{out, 0} = Task.await(task, 30_000)

frames = stats1 - stats0
cpu_ms = cpu1 - cpu0
wall_ms = wall1 - wall0

IO.puts("""
telemetry intake: #{length(Vehicles.list()) - 4} vehicles discovered of #{vehicles}, #{String.trim(out)} frames sent in #{seconds} s \
(#{round(String.to_integer(String.trim(out)) / seconds)} frames/s)
  measured over #{wall_ms} ms: #{frames} frames received (#{round(frames * 1000 / wall_ms)} frames/s), CPU #{cpu_ms} ms
  = #{Float.round(cpu_ms / wall_ms * 100, 1)} % of one core in all, #{Float.round(cpu_ms / wall_ms * 100 / vehicles, 3)} % per vehicle, \
#{Float.round(cpu_ms * 1000 / max(frames, 1), 1)} µs of CPU per frame
""")
