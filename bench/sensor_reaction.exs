# Reaction to a sensor: from the MAVLink frame that carries a reading to the
# stop of the task whose condition it makes true —
# until(task, sensor(v, :smoke) > 0.4) — beside the same measure for a
# battery report (SYS_STATUS) and until(task, battery(v) < 0.3).
#
# A stand-in vehicle (system id 42, a UDP socket of this VM) is heard on a
# real link on 127.0.0.1: its heartbeat, then, for each sample, the frame
# that crosses the threshold, sent from its companion computer's component
# (191: NAMED_VALUE_FLOAT "SMOKE") or its autopilot's (1: SYS_STATUS). The
# time is from just before the frame is sent to the fake platform task's
# stop callback: the datagram, the link's decoding and routing, the
# vehicle's process folding it into its view, the view published, the
# condition re-evaluated in the until's process, the stop sent down.
#
#   MIX_ENV=prod mix run bench/sensor_reaction.exs

alias Dolphin.Engine
alias Dolphin.Engine.{Cond, FakePlatform, Snapshot}
alias Dolphin.MAVLink.Ardupilotmega, as: M
alias Dolphin.MAVLink.Frame

Code.require_file("percentiles.exs", __DIR__)

sysid = 42
{:ok, _link} = Dolphin.Link.connect("udpin:127.0.0.1:0", name: "bench-sensors")
port = Dolphin.Link.Connection.port("bench-sensors")
{:ok, socket} = :gen_udp.open(0, [:binary, ip: {127, 0, 0, 1}, active: false])

seqs = :counters.new(2, [])

say = fn compid, message ->
  i = if compid == 1, do: 1, else: 2
  :counters.add(seqs, i, 1)
  bytes = Frame.encode(message, sysid: sysid, compid: compid, seq: rem(:counters.get(seqs, i), 256))
  :ok = :gen_udp.send(socket, {127, 0, 0, 1}, port, bytes)
end

heartbeat = %M.Heartbeat{type: 2, autopilot: 3, base_mode: 0, custom_mode: 0, system_status: 4, mavlink_version: 3}
say.(1, heartbeat)
say.(1, %M.SysStatus{battery_remaining: 90})

wait_view = fn wait_view, fun, tries ->
  case Dolphin.Vehicles.view(sysid) do
    {:ok, view} -> if fun.(view), do: view, else: (Process.sleep(10) && wait_view.(wait_view, fun, tries - 1))
    _ when tries > 0 -> Process.sleep(10) && wait_view.(wait_view, fun, tries - 1)
    other -> raise "the stand-in vehicle was not heard: #{inspect(other)}"
  end
end

{:ok, smoke} = Dolphin.Sensors.new(:smoke, from: {:named_value, "SMOKE"})
:ok = Dolphin.Vehicles.watch_sensors([smoke])
smoke_frame = fn value -> %M.NamedValueFloat{time_boot_ms: 0, name: "SMOKE", value: value} end
say.(191, smoke_frame.(0.1))
wait_view.(wait_view, &(Map.has_key?(&1.sensors, smoke.source) and &1.battery != nil), 500)
fleet = Dolphin.Instance.names().fleet
{:ok, _} = Dolphin.Fleet.pick(fleet, self(), id: sysid, timeout: 5_000)

# One sample: `until` on the vehicle, the crossing frame sent, its stop awaited; then back below.
sample = fn cond, cross, back ->
  task = FakePlatform.task("watch", duration: :infinity, notify: self())
  {:ok, run} = Engine.start(Engine.on(Engine.until(task, cond), [sysid]), fleet: fleet)
  receive do: ({:fake_platform, :started, _} -> :ok)
  t0 = System.monotonic_time()
  cross.()
  t1 = receive do: ({:fake_platform, :stopped, %{at: t1}} -> t1)
  {:ok, _} = Engine.await(run, 10_000)
  back.()
  # The vehicle's view says it is back below before the next sample.
  Process.sleep(5)
  System.convert_time_unit(t1 - t0, :native, :microsecond)
end

sensor_cond = Cond.new(fn snap -> Snapshot.sensor(snap, sysid, smoke) > 0.4 end, source: "sensor(v, :smoke) > 0.4")
battery_cond = Cond.new(fn snap -> Snapshot.battery(snap, sysid) < 0.3 end, source: "battery(v) < 0.3")

sensor_sample = fn -> sample.(sensor_cond, fn -> say.(191, smoke_frame.(0.6)) end, fn -> say.(191, smoke_frame.(0.1)) end) end
battery_sample = fn -> sample.(battery_cond, fn -> say.(1, %M.SysStatus{battery_remaining: 20}) end, fn -> say.(1, %M.SysStatus{battery_remaining: 90}) end) end

row = fn label, %{n: n, p50: p50, p99: p99, max: max} ->
  IO.puts(String.pad_trailing(label, 44) <> String.pad_leading("#{n}", 8) <> String.pad_leading("#{p50} µs", 12) <> String.pad_leading("#{p99} µs", 12) <> String.pad_leading("#{max} µs", 12))
end

IO.puts("reaction: frame sent -> stop callback (#{System.schedulers_online()} schedulers, OTP #{System.otp_release()}, Elixir #{System.version()})")
IO.puts(String.pad_trailing("", 44) <> String.pad_leading("samples", 8) <> String.pad_leading("p50", 12) <> String.pad_leading("p99", 12) <> String.pad_leading("max", 12))

# Warm-up (code loading, first allocations).
for _ <- 1..20, do: {sensor_sample.(), battery_sample.()}

# Alternated, so that both see the same machine.
{sensors, batteries} = Enum.unzip(for _ <- 1..300, do: {sensor_sample.(), battery_sample.()})
row.("NAMED_VALUE_FLOAT -> sensor(v, :smoke) > 0.4", Bench.Percentiles.of(sensors))
row.("SYS_STATUS -> battery(v) < 0.3", Bench.Percentiles.of(batteries))
