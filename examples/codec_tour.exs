# A tour of the MAVLink codec on the traffic of one ArduCopter and its ground
# station: encode, damage the stream as a bad radio link would, recover every
# intact frame, sign a command, and hand a .tlog to pymavlink.
#
#   mix run examples/codec_tour.exs
#
# (`make run` flies examples/two_vehicles.exs, not this; the scenario tests run
# this tour exactly so and check what it prints.) The last part needs the
# project's venv with pymavlink, which scripts/bootstrap creates.
alias Dolphin.MAVLink.{Frame, Message, Parser, Signing, Tlog}
alias Dolphin.MAVLink.Ardupilotmega, as: APM

{:ok, quad} = APM.enum_value(:mav_type, :mav_type_quadrotor)
{:ok, ardupilot} = APM.enum_value(:mav_autopilot, :mav_autopilot_ardupilotmega)
{:ok, waypoint} = APM.enum_value(:mav_cmd, :mav_cmd_nav_waypoint)
{:ok, relative_alt} = APM.enum_value(:mav_frame, :mav_frame_global_relative_alt_int)

vehicle = [
  %APM.Heartbeat{type: quad, autopilot: ardupilot, base_mode: 0x81 + 0x08, custom_mode: 4, system_status: 4},
  %APM.SysStatus{voltage_battery: 12_150, current_battery: 2_870, battery_remaining: 87},
  %APM.GlobalPositionInt{time_boot_ms: 61_250, lat: 411_780_000, lon: -85_960_000, alt: 132_000, relative_alt: 20_000, hdg: 9_000},
  %APM.Attitude{time_boot_ms: 61_250, roll: 0.01, pitch: -0.02, yaw: 1.5708},
  %APM.MissionItemInt{seq: 1, frame: relative_alt, command: waypoint, current: 0, autocontinue: 1,
                      param4: :nan, x: 411_785_400, y: -85_955_000, z: 20.0, target_system: 255},
  %APM.Statustext{severity: 6, text: "Flight plan received"}
]

IO.puts("== One vehicle's telemetry (sysid 1), MAVLink 2 with payload truncation")

frames =
  for {msg, seq} <- Enum.with_index(vehicle) do
    bytes = Frame.encode(msg, sysid: 1, compid: 1, seq: seq)
    full = msg.__struct__.__mavlink__(:max_len)
    IO.puts("  #{String.pad_trailing(Message.name(msg), 20)} id #{String.pad_leading("#{Message.id(msg)}", 3)}  #{byte_size(bytes)} bytes on the wire (payload #{byte_size(bytes) - 12} of #{full})")
    bytes
  end

IO.puts("\n== A bad radio link: garbage, a flipped bit, a frame cut short, all in odd-sized chunks")
:rand.seed(:exsss, {7, 7, 7})
garbage = fn -> :rand.bytes(:rand.uniform(40)) end
[hb, sys, pos, att, item, text] = frames
<<head::binary-size(20), byte, tail::binary>> = pos
flipped = <<head::binary, Bitwise.bxor(byte, 0x10), tail::binary>>
cut = binary_part(att, 0, 15)
stream = IO.iodata_to_binary([garbage.(), hb, garbage.(), sys, flipped, cut, item, garbage.(), text, hb])

{decoded, parser} =
  Stream.unfold(stream, fn
    <<>> -> nil
    rest -> n = min(:rand.uniform(17), byte_size(rest)); {binary_part(rest, 0, n), binary_part(rest, n, byte_size(rest) - n)}
  end)
  |> Enum.reduce({[], Parser.new()}, fn chunk, {acc, p} -> {f, p} = Parser.feed(p, chunk); {acc ++ f, p} end)

{rest, parser} = Parser.finish(parser)
decoded = decoded ++ rest
stats = Parser.stats(parser)
IO.puts("  recovered #{length(decoded)} frames: #{decoded |> Enum.map(&Message.name(&1.message)) |> Enum.join(", ")}")
IO.puts("  dropped: #{stats.bytes_skipped} bytes of #{stats.bytes}, #{stats.bad_crc} candidate frames failed their CRC (the flipped and the cut one among them)")
yaw = Enum.find(decoded, &match?(%APM.MissionItemInt{}, &1.message)).message.param4
IO.puts("  the waypoint's yaw is still #{inspect(yaw)}: NaN (\"keep heading\") survives the round trip")

IO.puts("\n== A signed command from the ground station (sysid 255), checked on arrival")
key = :crypto.hash(:sha256, "fleet secret")
{bytes, _gcs} = Signing.encode(Signing.new(key: key, link_id: 1), %APM.CommandLong{target_system: 1, command: 400, param1: 1.0}, sysid: 255, compid: 190)
{:ok, cmd, <<>>} = Frame.decode(bytes, APM)
{:ok, _} = Signing.verify(Signing.new(key: key, unsigned: :reject), cmd)
{:error, why, _} = Signing.verify(Signing.new(key: :crypto.hash(:sha256, "wrong")), cmd)
{:ok, command} = APM.enum_name(:mav_cmd, cmd.message.command)
IO.puts("  COMMAND_LONG #{inspect(command)}: accepted with the fleet key, #{why} with another")

IO.puts("\n== The telemetry as a .tlog, read back by pymavlink (the reference implementation)")
# Named after this OS process: two tours at once must not share the file.
path = Path.join(System.tmp_dir!(), "dolphin-tour-#{System.pid()}.tlog")
t0 = System.os_time(:microsecond)
File.write!(path, for({f, i} <- Enum.with_index(frames), do: Tlog.record(t0 + i * 100_000, f)))
python = Path.expand("../.venv/bin/python", __DIR__)

if File.exists?(python) do
  script = "import sys\nfrom pymavlink import mavutil\nm = mavutil.mavlink_connection(sys.argv[1])\nwhile True:\n    msg = m.recv_match(blocking=False)\n    if msg is None: break\n    print('  ' + msg.get_type(), {k: v for k, v in msg.to_dict().items() if k in ('battery_remaining', 'lat', 'text', 'param4')} or '')\n"
  {out, status} = System.cmd(python, ["-c", script, path], stderr_to_stdout: true)
  status == 0 || Mix.raise("pymavlink could not read #{path} (exit status #{status}):\n#{out}")
  IO.write(out)
else
  IO.puts("  (no .venv: run scripts/bootstrap to see pymavlink read it)")
end

File.rm(path)
