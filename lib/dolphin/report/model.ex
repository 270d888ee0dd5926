defmodule Dolphin.Report.Model do
  @moduledoc false
  # Turns a read log (FlightLog) and aligned events into what the page draws:
  # per vehicle, in metres east/north of one reference point and in clock
  # seconds from the log's first record, simplified to what the eye can tell.

  alias Dolphin.Report.{FlightLog, Simplify}
  alias Dolphin.Vehicles.View

  # Douglas–Peucker tolerance for tracks and planned paths, in metres.
  @track_tolerance_m 1.0
  # Time buckets of each plot: a plot is at most about 2x this many points.
  @plot_buckets 400
  # Above this height above home a vehicle is flying.
  @airborne_m 1.0
  # Samples of link counters over which a link's quality is measured.
  @link_window 5
  # A gap between two positions longer than this (clock s) is not flight time.
  @max_step_s 10.0
  # The most status texts per vehicle on the time line (the first ones).
  @max_texts 200

  @wgs84_a 6_378_137.0
  @wgs84_e2 6.69437999014e-3

  @doc false
  @spec build(FlightLog.t(), [map()], Dolphin.Report.Events.timeline()) :: map()
  # `timeline`: where an event goes on the log's time line
  # (Dolphin.Report.Events.align/3, place/2).
  def build(%FlightLog{} = log, events, timeline) do
    k = FlightLog.speedup(log)
    clock = FlightLog.clock(log)
    span = clock.(log.last_us)
    ids = log.vehicles |> Map.keys() |> Enum.sort()
    ref = reference(log, ids)
    project = projection(ref)
    events = Enum.map(events, &Map.put(&1, "t", Dolphin.Report.Events.place(timeline, &1["t_ms"])))
    tasks = tasks(events, span)

    sensors = sensors(events)

    vehicles =
      ids
      |> Enum.with_index()
      |> Enum.map(fn {id, i} -> vehicle(log.vehicles[id], i, clock, project, events, tasks, sensors) end)

    %{
      speedup: k,
      span_s: span,
      started_at: log.first_us && DateTime.from_unix!(log.first_us, :microsecond),
      stats: log.stats,
      vehicles: vehicles,
      script: script(events, span),
      script_marks: script_marks(events, tasks),
      separation: separation(log, events),
      sensors: sensors,
      detections: detections(events, project)
    }
  end

  @doc false
  # The sensors the run declared (its `sensor_declared` events), each once:
  # %{name, source, scale, offset, unit}; a source that names no message
  # field of the dialect (an events file from elsewhere) is left out.
  @spec sensors([map()]) :: [map()]
  def sensors(events) do
    for %{"event" => "sensor_declared", "sensor" => name, "source" => text} = e <- events,
        {:ok, source} <- [source(text)],
        uniq: true,
        do: %{name: name, source: source, scale: number(e["scale"], 1.0), offset: number(e["offset"], 0.0), unit: e["unit"]}
  end

  defp source("NAMED_VALUE " <> name), do: {:ok, {:named_value, name}}

  defp source(text) do
    with [message, field] <- String.split(text, ".", parts: 2),
         module when module != nil <- Dolphin.MAVLink.UserDialect.message_module(message),
         %{name: field} <- Enum.find(module.__mavlink__(:fields), &(Atom.to_string(&1.name) == field)) do
      {:ok, {:message, module, field}}
    else
      _ -> :error
    end
  end

  defp number(n, _default) when is_number(n), do: n
  defp number(_, default), do: default

  # Where sensors read what a script waited for (`sensor_threshold`), on the map.
  defp detections(events, project) do
    for %{"event" => "sensor_threshold", "lat" => lat, "lon" => lon} = e <- events, is_number(lat) and is_number(lon) do
      {x, y} = project.(lat * 1.0e7, lon * 1.0e7)
      %{x: x, y: y, t: e["t"], vehicle: e["vehicle"], sensor: e["sensor"], value: e["value"], unit: e["unit"], sent: e["sent"]}
    end
  end

  # The nearest-vehicle distance over time (Report.Separation) against the
  # least separation the monitor kept, as its events give it (else the default).
  defp separation(log, events) do
    limits =
      case Enum.find(events, &(&1["event"] == "separation_hold")) do
        %{"limit_m" => h, "limit_height_m" => v} when is_number(h) and h > 0 and is_number(v) and v > 0 -> %{horizontal: h, vertical: v}
        # None, or from an events file that does not say (an older one, one edited by hand).
        _ -> Dolphin.Separation.default_limits()
      end

    closest = Dolphin.Report.Separation.closest(log, vertical: limits.vertical)
    %{series: Simplify.series(closest.series, @plot_buckets), least: closest.least, limits: limits}
  end

  @doc false
  # What Events.align/3 matches the events against, in the log's clock seconds.
  @spec anchors(FlightLog.t()) :: map()
  def anchors(%FlightLog{} = log) do
    k = FlightLog.speedup(log)
    clock = FlightLog.clock(log)
    vs = Map.values(log.vehicles)

    %{
      vehicles: Enum.map(vs, & &1.id),
      span_s: if(log.first_us, do: clock.(log.last_us), else: 0.0),
      speedup: k,
      arming: Map.new(vs, fn v -> {v.id, for({ts, true} <- v.arming, do: clock.(ts))} end),
      # The first mode is where the vehicle was found, not a change.
      modes: Map.new(vs, fn v -> {v.id, for({ts, m} <- Enum.drop(v.modes, 1), do: {clock.(ts), m})} end),
      reached: Map.new(vs, fn v -> {v.id, for({ts, s} <- v.reached, do: {clock.(ts), s})} end),
      # Its autopilot's first heartbeat: the moment it was discovered.
      heard: Map.new(for v <- vs, [{ts, _, _} | _] <- [v.link], do: {v.id, clock.(ts)}),
      cut: log.stats != nil and log.stats.bytes_skipped > 0
    }
  end

  # --- geometry ---

  defp reference(log, ids) do
    homes = for id <- ids, {lat, lon, _} <- [log.vehicles[id].home], do: {lat / 1.0e7, lon / 1.0e7}
    firsts = for id <- ids, [{_, lat, lon, _, _, _} | _] <- [log.vehicles[id].positions], do: {lat / 1.0e7, lon / 1.0e7}

    case homes ++ firsts do
      [ref | _] -> ref
      [] -> {0.0, 0.0}
    end
  end

  # A local tangent plane at the reference: metres east and north. Over the
  # few kilometres of a flight its error is centimetres, and it costs a few
  # multiplications per point where Dolphin.Geo's geodesics would cost an
  # iteration: a report projects hundreds of thousands of points.
  defp projection({lat0, lon0}) do
    phi = lat0 * :math.pi() / 180
    s2 = :math.sin(phi) * :math.sin(phi)
    m = @wgs84_a * (1 - @wgs84_e2) / :math.pow(1 - @wgs84_e2 * s2, 1.5)
    n = @wgs84_a / :math.sqrt(1 - @wgs84_e2 * s2)
    ky = m * :math.pi() / 180 / 1.0e7
    kx = n * :math.cos(phi) * :math.pi() / 180 / 1.0e7
    lat0e7 = lat0 * 1.0e7
    lon0e7 = lon0 * 1.0e7
    fn lat_e7, lon_e7 -> {(lon_e7 - lon0e7) * kx, (lat_e7 - lat0e7) * ky} end
  end

  # --- one vehicle ---

  defp vehicle(v, index, clock, project, events, tasks, sensors) do
    points = for {ts, lat, lon, rel_mm, vx, vy} <- v.positions, {x, y} = project.(lat, lon), do: {clock.(ts), x, y, rel_mm / 1000, :math.sqrt(vx * vx + vy * vy) / 100}
    at = position_finder(points)
    {flight_s, distance, takeoffs, landings} = flight(points)
    mine = Enum.filter(events, &(&1["vehicle"] == v.id))
    my_tasks = Enum.filter(tasks, &(&1.vehicle == v.id))

    %{
      id: v.id,
      index: index,
      kind: kind(v),
      track: points |> Enum.map(fn {_, x, y, _, _} -> {x, y} end) |> Simplify.track(@track_tolerance_m),
      home: home(v.home, project),
      takeoffs: takeoffs,
      landings: landings,
      photos: for({ts, lat, lon} <- v.photos, {x, y} = project.(lat, lon), do: {clock.(ts), x, y}),
      plans: v.uploads |> Enum.map(&plan(&1, v.home, project, clock)) |> same_plans(),
      zones: zones(v.fence, project),
      rally: for({_seq, {5100, lat, lon, _z, _}} <- Enum.sort(v.rally), do: project.(lat, lon)),
      tasks: Enum.map(my_tasks, &Map.merge(&1, %{from: at.(&1.start), to: at.(&1.stop)})),
      marks: marks(v, mine, clock),
      series:
        %{
          battery: v.battery |> Enum.map(fn {ts, pct} -> {clock.(ts), pct} end) |> Simplify.series(@plot_buckets),
          height: points |> Enum.map(fn {t, _, _, h, _} -> {t, h} end) |> Simplify.series(@plot_buckets),
          speed: points |> Enum.map(fn {t, _, _, _, s} -> {t, s} end) |> Simplify.series(@plot_buckets),
          link: v.link |> link_quality(clock) |> Simplify.series(@plot_buckets)
        }
        |> Map.merge(
          Map.new(sensors, fn s ->
            readings = Map.get(v.sensors, s.source, [])
            {{:sensor, s.name}, readings |> Enum.map(fn {ts, raw} -> {clock.(ts), raw * s.scale + s.offset} end) |> Simplify.series(@plot_buckets)}
          end)
        ),
      summary: %{
        flight_s: flight_s,
        distance_m: distance,
        reached: length(v.reached),
        photos: length(v.photos),
        lowest_battery: v.battery |> Enum.map(&elem(&1, 1)) |> Enum.min(fn -> nil end),
        failures: for(%{result: "failed"} = t <- my_tasks, do: {t.name, t.reason})
      }
    }
  end

  # Its type and airframe, as its heartbeats said (Dolphin.Vehicles.View).
  defp kind(%{type: nil}), do: nil
  defp kind(v), do: View.describe_kind(%View{type: View.class(v.type), airframe: View.airframe(v.type, v.autopilot), mav_type: v.type})

  defp home(nil, _project), do: nil
  defp home({lat, lon, _}, project), do: project.(lat, lon)

  # Flight time and distance flown (the steps between two positions both
  # above @airborne_m; distance over every step: a rover drives on the
  # ground), and where the vehicle left the ground and came back to it. One
  # pass: an hour at 10 Hz is 36,000 positions per vehicle.
  defp flight([]), do: {0.0, 0.0, [], []}
  defp flight([first | rest]), do: flight(rest, first, 0.0, 0.0, [], [])

  defp flight([], _prev, time, dist, up, down), do: {time, dist, Enum.reverse(up), Enum.reverse(down)}

  defp flight([{t2, x2, y2, h2, _} = p | rest], {t1, x1, y1, h1, _}, time, dist, up, down) do
    dt = t2 - t1
    time = if h1 > @airborne_m and h2 > @airborne_m and dt <= @max_step_s, do: time + dt, else: time
    dist = dist + :math.sqrt((x2 - x1) * (x2 - x1) + (y2 - y1) * (y2 - y1))

    cond do
      h1 <= @airborne_m and h2 > @airborne_m -> flight(rest, p, time, dist, [{t2, x1, y1} | up], down)
      h1 > @airborne_m and h2 <= @airborne_m -> flight(rest, p, time, dist, up, [{t2, x2, y2} | down])
      true -> flight(rest, p, time, dist, up, down)
    end
  end

  # Where the vehicle was at clock time t: the last position at or before it
  # (the first one before the first), nil without positions.
  defp position_finder([]), do: fn _ -> nil end

  defp position_finder(points) do
    t = List.to_tuple(points)

    fn
      nil ->
        nil

      time ->
        {_, x, y, _, _} = elem(t, search(t, time, 0, tuple_size(t) - 1))
        {x, y}
    end
  end

  defp search(_t, _time, lo, hi) when lo >= hi, do: lo

  defp search(t, time, lo, hi) do
    mid = div(lo + hi + 1, 2)
    if elem(elem(t, mid), 0) <= time, do: search(t, time, mid, hi), else: search(t, time, lo, mid - 1)
  end

  # The planned path of one upload: its navigation items with a position, in
  # order (home first, as ArduPilot takes item 0), a return-to-launch back home.
  @nav_with_position [16, 17, 18, 19, 21, 22, 31]
  @rtl 20

  defp plan(upload, home, project, clock) do
    home_xy = home(home, project)

    points =
      upload.items
      |> Enum.sort()
      |> Enum.flat_map(fn
        {seq, {cmd, lat, lon, _z}} when cmd in @nav_with_position and (lat != 0 or lon != 0) ->
          {x, y} = project.(lat, lon)
          [{seq, cmd, x, y}]

        {seq, {@rtl, _, _, _}} when home_xy != nil ->
          {x, y} = home_xy
          [{seq, @rtl, x, y}]

        _ ->
          []
      end)

    %{at: clock.(upload.at), count: upload.count, points: points}
  end

  # The zones of the latest fence uploaded (read as the vehicle keeps them,
  # Dolphin.Fence.from_items/1), in map metres.
  defp zones(items, project) do
    fence = items |> Enum.sort() |> Enum.map(fn {_seq, {command, x, y, _z, param1}} -> %{command: command, x: x, y: y, param1: param1} end) |> Dolphin.Fence.from_items()
    at = fn %{lat: lat, lon: lon} -> project.(round(lat * 1.0e7), round(lon * 1.0e7)) end
    Enum.map(fence.include, &zone(&1, true, at)) ++ Enum.map(fence.exclude, &zone(&1, false, at))
  end

  defp zone(%Dolphin.Geo.Polygon{points: points}, inclusion?, at), do: %{shape: :polygon, inclusion?: inclusion?, points: Enum.map(points, at)}
  defp zone(%Dolphin.Geo.Circle{centre: c, radius: r}, inclusion?, at), do: %{shape: :circle, inclusion?: inclusion?, centre: at.(c), radius: r}

  # A mission uploaded again (each `forever` round of a script) is drawn once,
  # with the times it was uploaded.
  defp same_plans(plans) do
    plans
    |> Enum.group_by(& &1.points)
    |> Enum.map(fn {_points, [first | _] = same} -> Map.put(first, :times, Enum.map(same, & &1.at)) end)
    |> Enum.sort_by(& &1.at)
  end

  defp link_quality(samples, clock) do
    samples
    |> Enum.chunk_every(@link_window + 1, 1, :discard)
    |> Enum.flat_map(fn window ->
      {_, r0, l0} = hd(window)
      {ts, r1, l1} = List.last(window)
      total = r1 - r0 + (l1 - l0)
      if total > 0, do: [{clock.(ts), 100 * (r1 - r0) / total}], else: []
    end)
  end

  # Marks on a vehicle's lane: from the events when there are any (what the
  # ground station saw), else from the log; status texts always from the log.
  defp marks(v, [], clock) do
    modes = for {ts, m} <- Enum.drop(v.modes, 1), do: {clock.(ts), :mode, "mode #{mode_name(m)}"}
    modes ++ texts(v, clock)
  end

  defp marks(v, events, clock) do
    from_events =
      Enum.flat_map(events, fn
        %{"event" => "mode_changed", "mode" => m, "t" => t} -> [{t, :mode, "mode #{m}"}]
        %{"event" => "vehicle_lost", "t" => t} -> [{t, :lost, "lost"}]
        %{"event" => "vehicle_reconnected", "t" => t} -> [{t, :reconnected, "reconnected"}]
        %{"event" => "separation_hold", "t" => t} = e -> [{t, :separation_hold, "held apart from vehicle #{e["other"]} (#{e["distance"]} m away)"}]
        %{"event" => "separation_clear", "t" => t} = e -> [{t, :separation_clear, "goes on after #{e["held_ms"] / 1000} s held"}]
        _ -> []
      end)

    from_events ++ texts(v, clock)
  end

  defp texts(v, clock), do: v.texts |> Enum.take(@max_texts) |> Enum.map(fn {ts, _sev, text} -> {clock.(ts), :text, text} end)

  defp mode_name({:custom, n}), do: "custom #{n}"
  defp mode_name(m), do: to_string(m)

  # --- the script ---

  # Tasks from their start and end events; one never finished ends with the log.
  defp tasks(events, span) do
    finished = for %{"event" => "task_finished"} = e <- events, into: %{}, do: {{e["run"], e["task_id"]}, e}

    for %{"event" => "task_started"} = e <- events do
      f = Map.get(finished, {e["run"], e["task_id"]})

      %{
        key: {e["run"], e["task_id"]},
        parent: {e["run"], e["parent_id"]},
        name: e["name"] || "",
        kind: e["kind"] || "",
        vehicle: e["vehicle"],
        start: e["t"],
        stop: if(f, do: f["t"], else: max(span, e["t"])),
        result: if(f, do: f["result"] || "unknown", else: "unfinished"),
        reason: f && f["reason"]
      }
    end
  end

  defp script(events, span) do
    started = Enum.find(events, &(&1["event"] == "script_started"))
    finished = Enum.find(events, &(&1["event"] == "script_finished"))

    if started || finished do
      %{
        name: (started || finished)["script"],
        start: started && started["t"],
        stop: if(finished, do: finished["t"], else: span),
        result: if(finished, do: finished["result"], else: "unfinished"),
        reason: finished && finished["reason"]
      }
    end
  end

  # Conditions met and messages, each with the one vehicle it concerns (the
  # vehicle of every platform task under the condition's task) or none.
  defp script_marks(events, tasks) do
    parents = Map.new(tasks, &{&1.key, &1.parent})

    vehicles_under =
      tasks
      |> Enum.filter(& &1.vehicle)
      |> Enum.flat_map(fn t -> t.key |> ancestors(parents) |> Enum.map(&{&1, t.vehicle}) end)
      |> Enum.group_by(&elem(&1, 0), &elem(&1, 1))

    Enum.flat_map(events, fn
      %{"event" => "condition_met", "t" => t} = e ->
        vehicle =
          case Enum.uniq(Map.get(vehicles_under, {e["run"], e["task_id"]}, [])) do
            [one] -> one
            _ -> nil
          end

        [{t, :condition, "condition met: #{e["condition"]}", vehicle}]

      %{"event" => "message", "t" => t, "text" => text} ->
        [{t, :message, "message: #{text}", nil}]

      %{"event" => "pick_failed", "t" => t} = e ->
        [{t, :failure, "pick failed: #{e["reason"]}", nil}]

      _ ->
        []
    end)
  end

  # A task and its ancestors; a damaged file's loop of parents ends where it closes.
  defp ancestors(key, parents, acc \\ []) do
    case Map.fetch(parents, key) do
      {:ok, parent} -> if key in acc, do: acc, else: ancestors(parent, parents, [key | acc])
      :error -> [key | acc]
    end
  end
end
