# The live separation monitor's reaction time, and how far apart it kept two
# vehicles, measured on the wire: examples/crossing_paths.exs flown RUNS times
# (two copters whose ways cross at one moment), each run's .tlog read back.
#
#   reaction:  from the position frame after which the two vehicles' straight
#              paths (the same prediction as the monitor's: their positions
#              and velocities, 8 s ahead, 20 m across / 10 m in height) first
#              lose separation, to the first DO_SET_MODE the ground station
#              sends the vehicle it holds: both are stamped by the link as it
#              receives and sends them (wall-clock microseconds).
#   least:     the nearest the two came, across, while within 10 m in height
#              (Dolphin.Report.Separation).
#
#   MIX_ENV=prod mix run bench/separation.exs [--runs N] [--speedup S] [--sitl]
#
# The reaction is the ground station's (view, prediction, the executor's
# command); the telemetry's period (2 Hz of vehicle time) comes before it and
# is not counted.

alias Dolphin.MAVLink.Ardupilotmega, as: M
alias Dolphin.MAVLink.Tlog
alias Dolphin.Separation.Prediction

{opts, _, _} = OptionParser.parse(System.argv(), strict: [runs: :integer, speedup: :integer, sitl: :boolean])
runs = Keyword.get(opts, :runs, 5)
speedup = Keyword.get(opts, :speedup, 10)
backend = if opts[:sitl], do: "--sitl", else: "--sim"
example = Path.expand("../examples/crossing_paths.exs", __DIR__)
dir = Path.join(System.tmp_dir!(), "dolphin-bench-separation-#{System.unique_integer([:positive])}")
File.mkdir_p!(dir)

Code.require_file("percentiles.exs", __DIR__)

defmodule SeparationBench do
  @limits Dolphin.Separation.default_limits()
  @mode_command 176

  # {reaction µs, the held vehicle} of one run's log: the hold's DO_SET_MODE
  # against the first frame that showed the loss of separation coming.
  # `k`: the log's vehicle seconds per wall second (Dolphin.Report.FlightLog.speedup/1).
  def reaction(path, k) do
    {records, reader} = Tlog.read(Tlog.reader(), File.read!(path))
    {rest, _} = Tlog.finish(reader)
    records = records ++ rest

    # GUIDED (4) and AUTO (3) start and resume missions; the other is the hold (BRAKE).
    [{sent_us, held} | _] = for {ts, %{message: %M.CommandLong{command: @mode_command, target_system: v, param2: mode}}} <- records, mode not in [3.0, 4.0], do: {ts, v}

    # Only frames before the hold count, of vehicles in the air (latest: the vehicles' last such frames).
    trigger =
      records
      |> Enum.filter(fn {ts, f} -> ts < sent_us and airborne?(f.message) end)
      |> Enum.reduce_while(%{}, fn {ts, f}, latest ->
        latest = Map.put(latest, f.sysid, {ts, f.message})

        case Map.values(latest) do
          [a, b] -> if conflict?(a, b, ts, k), do: {:halt, {:found, ts}}, else: {:cont, latest}
          _ -> {:cont, latest}
        end
      end)

    case trigger do
      {:found, ts} -> {sent_us - ts, held}
      _ -> {nil, held}
    end
  end

  # A position the monitor judges: placed (SITL reports zeros until its GPS has a fix), and in the air.
  defp airborne?(%M.GlobalPositionInt{lat: lat, relative_alt: rel}), do: lat != 0 and rel > 1_000
  defp airborne?(_message), do: false

  defp conflict?({ta, a}, {tb, b}, now, k) do
    plane = Dolphin.Geo.tangent_plane(%{lat: a.lat / 1.0e7, lon: a.lon / 1.0e7})
    Prediction.conflict(motion(plane, a, (now - ta) / 1.0e6 * k), motion(plane, b, (now - tb) / 1.0e6 * k), @limits, 8) != :clear
  end

  # Position moved on by its velocity for `age_s` seconds of vehicle time.
  defp motion(plane, p, age_s) do
    {vn, ve, vu} = {p.vx / 100, p.vy / 100, -p.vz / 100}
    {n, e} = Dolphin.Geo.to_tangent(plane, p.lat / 1.0e7, p.lon / 1.0e7)
    {{n + vn * age_s, e + ve * age_s, p.alt / 1000 + vu * age_s}, {vn, ve, vu}}
  end
end

IO.puts("separation monitor: #{runs} run(s) of examples/crossing_paths.exs on #{backend} 2 at #{speedup}x")

results =
  for i <- 1..runs do
    tlog = Path.join(dir, "run#{i}.tlog")
    {:ok, out} = StringIO.open("")
    argv = [example, backend, "2", "--speedup", "#{speedup}", "--tlog", tlog, "--quiet"]
    code = Mix.Tasks.Dolphin.Run.main(argv, out: out, err: out)
    if code != 0, do: raise("run #{i} exited #{code}: #{elem(StringIO.contents(out), 1)}")
    {:ok, log} = Dolphin.Report.FlightLog.read_file(tlog)
    least = Dolphin.Report.Separation.closest(log).least
    {reaction_us, held} = SeparationBench.reaction(tlog, Dolphin.Report.FlightLog.speedup(log))
    IO.puts("  run #{i}: vehicle #{held} held, reaction #{if reaction_us, do: "#{Float.round(reaction_us / 1000, 2)} ms", else: "?"}, least #{Float.round(least.across, 1)} m across")
    {reaction_us, least.across}
  end

reactions = for {us, _} <- results, us != nil, do: us / 1000
leasts = for {_, m} <- results, do: m
%{p50: p50} = Bench.Percentiles.of(reactions)
IO.puts("reaction (frame -> hold command): min #{Float.round(Enum.min(reactions), 2)} ms, median #{Float.round(p50, 2)} ms, max #{Float.round(Enum.max(reactions), 2)} ms")
IO.puts("least separation across: min #{Float.round(Enum.min(leasts), 1)} m, max #{Float.round(Enum.max(leasts), 1)} m (limit 20 m)")
File.rm_rf!(dir)
