# Time and size of a flight report of a large run: a synthesised telemetry log
# of 1 hour of 10 vehicles, each sending GLOBAL_POSITION_INT at 10 Hz (360,000
# positions in all) with HEARTBEAT, SYS_STATUS and VFR_HUD at 1 Hz, each flying
# a lawnmower survey of its own strip at 8 m/s with GPS noise of ±0.3 m, after
# an upload of its mission (MISSION_COUNT + MISSION_ITEM_INT from the ground
# station). Prints the time Dolphin.Report.write/4 takes (reading, simplifying,
# rendering, writing) and the page's size; the goal is under 10 s and 5 MB.
#
#   MIX_ENV=prod mix run bench/report.exs
#
# Environment: BENCH_VEHICLES (default 10), BENCH_MINUTES (default 60),
# BENCH_ROUNDS (default 3), BENCH_KEEP=1 keeps the files in the system's tmp.
defmodule ReportBench do
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.{Frame, Tlog}

  @lat0 40.444233
  @lon0 -7.375234
  @m_per_deg_lat 111_035.0
  @hz 10
  @speed 8.0
  @leg_m 800.0
  @spacing_m 40.0

  def main do
    vehicles = env("BENCH_VEHICLES", 10)
    minutes = env("BENCH_MINUTES", 60)
    rounds = env("BENCH_ROUNDS", 3)
    dir = Path.join(System.tmp_dir!(), "dolphin-report-bench-#{System.unique_integer([:positive])}")
    File.mkdir_p!(dir)
    tlog = Path.join(dir, "bench.tlog")
    out = Path.join(dir, "bench.html")

    {us, positions} = :timer.tc(fn -> synthesise(tlog, vehicles, minutes) end)
    IO.puts("synthesised #{positions} positions of #{vehicles} vehicles over #{minutes} min: #{mb(File.stat!(tlog).size)} of tlog in #{secs(us)}")

    times =
      for _ <- 1..rounds do
        {us, {:ok, summary}} = :timer.tc(fn -> Dolphin.Report.write(tlog, nil, out) end)
        {us, summary}
      end

    {best, summary} = Enum.min_by(times, &elem(&1, 0))
    median = times |> Enum.map(&elem(&1, 0)) |> Enum.sort() |> Enum.at(div(rounds, 2))
    html = File.read!(out)
    points = Regex.scan(~r/class="flown"[^>]*data-points="(\d+)"/, html) |> Enum.map(fn [_, n] -> String.to_integer(n) end) |> Enum.sum()

    IO.puts("report of #{summary.frames} frames: best #{secs(best)}, median #{secs(median)} of #{rounds}; #{mb(summary.bytes)}; tracks of #{positions} positions drawn with #{points} points")
    if System.get_env("BENCH_KEEP") == "1", do: IO.puts("kept #{dir}"), else: File.rm_rf!(dir)
  end

  defp env(name, default), do: String.to_integer(System.get_env(name, Integer.to_string(default)))
  defp secs(us), do: "#{:erlang.float_to_binary(us / 1_000_000, decimals: 2)} s"
  defp mb(bytes), do: "#{:erlang.float_to_binary(bytes / 1_048_576, decimals: 2)} MB"

  # Written a second at a time, every vehicle's frames of that second in time order.
  defp synthesise(path, vehicles, minutes) do
    t0 = 1_800_000_000_000_000
    seconds = minutes * 60
    :rand.seed(:exsss, {1, 2, 3})
    io = File.open!(path, [:write, :binary, :raw, :delayed_write])

    for v <- 1..vehicles do
      write(io, t0, upload(v))
    end

    for s <- 0..(seconds - 1) do
      records =
        for v <- 1..vehicles, i <- 0..(@hz - 1) do
          t = s + i / @hz
          ts = t0 + 5_000_000 + round(t * 1_000_000) + v * 997
          {ts, v, position(v, t)}
        end

      slow =
        for v <- 1..vehicles do
          ts = t0 + 5_000_000 + s * 1_000_000 + v * 1_013
          battery = max(0, 100 - div(s * 100, seconds + 600))

          [
            {ts, v, %M.Heartbeat{type: 2, autopilot: 3, base_mode: 0x81 + 0x10, custom_mode: 3, system_status: 4, mavlink_version: 3}},
            {ts + 1, v, %M.SysStatus{battery_remaining: battery, voltage_battery: 12_000}},
            {ts + 2, v, %M.VfrHud{groundspeed: @speed, alt: 50.0}}
          ]
        end

      # Each vehicle numbers its frames in the order it sends them: 13 a second.
      (records ++ List.flatten(slow))
      |> Enum.sort_by(&elem(&1, 0))
      |> Enum.reduce(%{}, fn {ts, v, msg}, sent ->
        k = Map.get(sent, v, 0)
        IO.binwrite(io, Tlog.record(ts, Frame.encode(msg, sysid: v, compid: 1, seq: rem(s * 13 + k, 256))))
        Map.put(sent, v, k + 1)
      end)
    end

    File.close(io)
    vehicles * seconds * @hz
  end

  defp write(io, ts, frames), do: Enum.each(frames, &IO.binwrite(io, Tlog.record(ts, &1)))

  # Vehicle v's strip starts 1 km east of the previous one's.
  defp origin(v), do: {0.0, (v - 1) * 1000.0}

  defp upload(v) do
    {n0, e0} = origin(v)
    legs = 20
    corners = for leg <- 0..(legs - 1), end_ <- [0, 1], do: {n0 + if(rem(leg, 2) == end_, do: 0.0, else: @leg_m), e0 + leg * @spacing_m}
    items = [{n0, e0} | corners]

    [Frame.encode(%M.MissionCount{target_system: v, target_component: 1, count: length(items)}, sysid: 255, compid: 190)] ++
      Enum.with_index(items, fn {n, e}, seq ->
        {lat, lon} = latlon(n, e)
        Frame.encode(%M.MissionItemInt{target_system: v, target_component: 1, seq: seq, frame: 5, command: 16, x: lat, y: lon, z: 50.0, autocontinue: 1}, sysid: 255, compid: 190)
      end)
  end

  # Back and forth along the strip's legs at @speed, 50 m up, with noise.
  defp position(v, t) do
    {n0, e0} = origin(v)
    along = t * @speed
    leg = trunc(along / (@leg_m + @spacing_m))
    into = along - leg * (@leg_m + @spacing_m)
    {north, east} = if into < @leg_m, do: {into, 0.0}, else: {@leg_m, into - @leg_m}
    north = if rem(leg, 2) == 0, do: north, else: @leg_m - north
    noise = fn -> (:rand.uniform() - 0.5) * 0.6 end
    {lat, lon} = latlon(n0 + north + noise.(), e0 + leg * @spacing_m + east + noise.())
    %M.GlobalPositionInt{time_boot_ms: round(t * 1000) + 5000, lat: lat, lon: lon, alt: 870_000, relative_alt: 50_000, vx: 800, vy: 0, vz: 0, hdg: 0}
  end

  defp latlon(north, east) do
    lat = @lat0 + north / @m_per_deg_lat
    lon = @lon0 + east / (@m_per_deg_lat * :math.cos(@lat0 * :math.pi() / 180))
    {round(lat * 1.0e7), round(lon * 1.0e7)}
  end
end

ReportBench.main()
