defmodule Dolphin.Report.SVG do
  @moduledoc false
  # Draws a report's model (Report.Model) as inline SVG: the map, the time
  # line and the plots. iodata all the way; numbers to a decimal or two.

  import Dolphin.Report.HTML, only: [esc: 1, num: 1, num: 2, color: 1, clock: 1]

  @width 1200
  @label_w 120
  @right_pad 20
  # Width over height of the map (the page's CSS gives its box the same).
  @map_aspect 1.6

  # --- the map ---

  @doc false
  @spec map(map()) :: iodata()
  def map(model) do
    {minx, miny, maxx, maxy} = model.vehicles |> bounds() |> widen()
    w = maxx - minx
    h = maxy - miny
    span = max(w, h)
    r = span / 160
    font = span / 80
    homes = Enum.map(model.vehicles, &(&1.home && {round(elem(&1.home, 0) / r), round(elem(&1.home, 1) / r)}))
    shared = homes |> Enum.frequencies() |> Enum.filter(fn {h, n} -> h != nil and n > 1 end) |> Map.new()
    shared_homes = for v <- model.vehicles, v.home != nil, Map.has_key?(shared, {round(elem(v.home, 0) / r), round(elem(v.home, 1) / r)}), do: v.home
    ctx = %{r: r, font: font, shared_homes: shared_homes}

    [
      ~s(<svg id="map" class="map" xmlns="http://www.w3.org/2000/svg" viewBox="#{num(minx)} #{num(-maxy)} #{num(w)} #{num(h)}" preserveAspectRatio="xMidYMid meet" data-span-m="#{num(span, 0)}">),
      grid(minx, miny, maxx, maxy, span),
      model.vehicles |> Enum.flat_map(& &1.zones) |> Enum.uniq() |> Enum.map(&zone/1),
      Enum.map(model.vehicles, &vehicle_map(&1, ctx)),
      model.vehicles |> Enum.flat_map(& &1.rally) |> Enum.uniq() |> Enum.map(&rally_point(&1, font)),
      Enum.map(Map.get(model, :detections, []), &detection(&1, r)),
      scale_bar(minx, miny, span, font, nice(span / 8)),
      north_arrow(maxx, maxy, span, font),
      "</svg>"
    ]
  end

  defp bounds(vehicles) do
    xs_ys =
      Enum.flat_map(vehicles, fn v ->
        v.track ++ Enum.flat_map(v.plans, fn p -> Enum.map(p.points, fn {_, _, x, y} -> {x, y} end) end) ++ List.wrap(v.home) ++ zone_points(Map.get(v, :zones, []))
      end)

    case xs_ys do
      [] ->
        {-50.0, -50.0, 50.0, 50.0}

      pts ->
        {xs, ys} = Enum.unzip(pts)
        {minx, maxx} = Enum.min_max(xs)
        {miny, maxy} = Enum.min_max(ys)
        # Never narrower than 50 m: a vehicle that stayed put still gets a map.
        cx = (minx + maxx) / 2
        cy = (miny + maxy) / 2
        half = max(25.0, max(maxx - minx, maxy - miny) / 2)
        {min(minx, cx - half), min(miny, cy - half), max(maxx, cx + half), max(maxy, cy + half)}
    end
  end

  # A margin around what is drawn, and the page's aspect, so the grid fills it.
  defp widen({minx, miny, maxx, maxy}) do
    pad = max(maxx - minx, maxy - miny) * 0.06
    {w, h} = {maxx - minx + 2 * pad, maxy - miny + 2 * pad}
    {w, h} = {max(w, h * @map_aspect), max(h, w / @map_aspect)}
    {cx, cy} = {(minx + maxx) / 2, (miny + maxy) / 2}
    {cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2}
  end

  defp grid(minx, miny, maxx, maxy, span) do
    step = nice(span / 8)
    xs = Stream.iterate(Float.ceil(minx / step) * step, &(&1 + step)) |> Enum.take_while(&(&1 <= maxx))
    ys = Stream.iterate(Float.ceil(miny / step) * step, &(&1 + step)) |> Enum.take_while(&(&1 <= maxy))

    [
      ~s(<g class="grid" data-step-m="#{num(step, 0)}">),
      Enum.map(xs, &~s(<line x1="#{num(&1)}" y1="#{num(-maxy)}" x2="#{num(&1)}" y2="#{num(-miny)}"/>)),
      Enum.map(ys, &~s(<line x1="#{num(minx)}" y1="#{num(-&1)}" x2="#{num(maxx)}" y2="#{num(-&1)}"/>)),
      "</g>"
    ]
  end

  defp scale_bar(minx, miny, span, font, grid_step) do
    len = nice(span / 5)
    x = minx + span * 0.03
    y = -(miny + span * 0.04)

    [
      ~s(<g class="scale-bar" data-length-m="#{num(len, 0)}">),
      ~s(<rect x="#{num(x)}" y="#{num(y - font * 0.4)}" width="#{num(len)}" height="#{num(font * 0.4)}"/>),
      ~s(<text x="#{num(x)}" y="#{num(y - font * 0.7)}" font-size="#{num(font)}">#{metres(len)} · grid #{metres(grid_step)}</text>),
      "</g>"
    ]
  end

  defp north_arrow(maxx, maxy, span, font) do
    x = maxx - span * 0.04
    y = -(maxy - span * 0.04)
    s = font * 1.6

    [
      ~s(<g class="north-arrow"><path d="M#{num(x)} #{num(y)} L#{num(x + s * 0.4)} #{num(y + s * 1.2)} L#{num(x)} #{num(y + s * 0.9)} L#{num(x - s * 0.4)} #{num(y + s * 1.2)} Z"/>),
      ~s(<text x="#{num(x)}" y="#{num(y + s * 1.2 + font * 1.1)}" font-size="#{num(font)}" text-anchor="middle">N</text></g>)
    ]
  end

  defp metres(m) when m >= 1000, do: "#{num(m / 1000, 1)} km"
  defp metres(m), do: "#{num(m, 0)} m"

  # A fence's zone: an inclusion zone outlined, an exclusion (no-fly) zone shaded.
  defp zone(%{shape: :polygon, inclusion?: inclusion?, points: points}),
    do: [~s(<polygon class="zone #{side(inclusion?)}" points="), points(points), ~s("><title>fence: #{side(inclusion?)} zone</title></polygon>)]

  defp zone(%{shape: :circle, inclusion?: inclusion?, centre: {x, y}, radius: r}),
    do: ~s(<circle class="zone #{side(inclusion?)}" cx="#{num(x)}" cy="#{num(-y)}" r="#{num(r)}"><title>fence: #{side(inclusion?)} zone, #{metres(r)} radius</title></circle>)

  # Where a sensor read what the script waited for: a ring and its centre.
  defp detection(d, r) do
    sent = if d.sent, do: "; vehicle #{d.sent} sent to look", else: ""
    title = "#{esc(to_string(d.sensor))} #{d.value}#{if d.unit, do: " #{esc(to_string(d.unit))}"} read by vehicle #{d.vehicle} at #{num(d.t, 1)} s#{sent}"

    [
      ~s(<g class="detection-mark"><circle class="detection" cx="#{num(d.x)}" cy="#{num(-d.y)}" r="#{num(r * 4)}"/>),
      ~s(<circle class="detection-dot" cx="#{num(d.x)}" cy="#{num(-d.y)}" r="#{num(r)}"/><title>#{title}</title></g>)
    ]
  end

  defp side(true), do: "inclusion"
  defp side(false), do: "exclusion"

  defp rally_point({x, y}, font),
    do: ~s(<text class="rally" x="#{num(x)}" y="#{num(-y)}" font-size="#{num(font * 1.2)}" text-anchor="middle"><title>rally point</title>R</text>)

  defp zone_points(zones) do
    Enum.flat_map(zones, fn
      %{shape: :polygon, points: points} -> points
      %{shape: :circle, centre: {x, y}, radius: r} -> [{x - r, y - r}, {x + r, y + r}]
    end)
  end

  defp vehicle_map(v, ctx) do
    c = color(v.index)
    r = ctx.r

    [
      ~s(<g class="vehicle v-#{v.id}" data-vehicle="#{v.id}" style="--c:#{c}">),
      Enum.with_index(v.plans, fn p, i ->
        [
          ~s(<polyline class="planned" data-vehicle="#{v.id}" data-upload="#{i + 1}" points="),
          points(Enum.map(p.points, fn {_, _, x, y} -> {x, y} end)),
          ~s|"><title>vehicle #{v.id}: mission of #{p.count} items uploaded at #{Enum.map_join(p.times, ", ", &clock/1)}</title></polyline>|,
          Enum.map(p.points, fn {seq, cmd, x, y} ->
            ~s|<circle class="item" cx="#{num(x)}" cy="#{num(-y)}" r="#{num(r * 0.6)}"><title>vehicle #{v.id}, upload #{i + 1}: item #{seq} (#{command(cmd)})</title></circle>|
          end)
        ]
      end),
      ~s(<polyline class="flown" data-vehicle="#{v.id}" data-points="#{length(v.track)}" points="),
      points(v.track),
      ~s("><title>vehicle #{v.id}: flown track</title></polyline>),
      Enum.map(v.tasks, fn t -> [task_point(v, t, t.from, :start, r), task_point(v, t, t.to, :end, r)] end),
      Enum.map(v.photos, fn {t, x, y} ->
        ~s(<rect class="photo" x="#{num(x - r * 0.5)}" y="#{num(-y - r * 0.5)}" width="#{num(r)}" height="#{num(r)}"><title>vehicle #{v.id}: photo at #{clock(t)}</title></rect>)
      end),
      Enum.map(v.takeoffs, fn {t, x, y} -> triangle("takeoff", x, y, r * 1.6, false, "vehicle #{v.id}: take-off at #{clock(t)}") end),
      Enum.map(v.landings, fn {t, x, y} -> triangle("landing", x, y, r * 1.6, true, "vehicle #{v.id}: landing at #{clock(t)}") end),
      home_mark(v, r, ctx.font, v.home in ctx.shared_homes),
      "</g>"
    ]
  end

  defp home_mark(%{home: nil}, _r, _font, _shared), do: []

  defp home_mark(%{home: {x, y}, id: id, index: i}, r, font, shared) do
    s = r * 1.5
    # Above the mark; vehicles sharing a home get their labels one above the other.
    ly = -y - s - font * 0.3 - i * font * 0.9 * if(shared, do: 1, else: 0)

    [
      ~s(<g class="home" data-vehicle="#{id}"><rect x="#{num(x - s)}" y="#{num(-y - s)}" width="#{num(2 * s)}" height="#{num(2 * s)}"/>),
      ~s(<text x="#{num(x)}" y="#{num(ly)}" font-size="#{num(font * 0.8)}" text-anchor="middle">H#{id}</text><title>vehicle #{id}: home</title></g>)
    ]
  end

  defp task_point(_v, _t, nil, _which, _r), do: []

  defp task_point(v, t, {x, y}, which, r) do
    when_s = if which == :start, do: t.start, else: t.stop
    what = if which == :start, do: "started", else: "ended (#{t.result})"

    ~s(<circle class="task-#{which} result-#{esc(t.result)}" cx="#{num(x)}" cy="#{num(-y)}" r="#{num(r)}"><title>vehicle #{v.id}: #{esc(t.kind)} “#{esc(t.name)}” #{what} at #{clock(when_s)}</title></circle>)
  end

  defp triangle(class, x, y, s, down, title) do
    d = if down, do: 1, else: -1

    ~s(<path class="#{class}" d="M#{num(x)} #{num(-y + d * s)} L#{num(x + s)} #{num(-y - d * s * 0.7)} L#{num(x - s)} #{num(-y - d * s * 0.7)} Z"><title>#{title}</title></path>)
  end

  defp points(list), do: Enum.map_intersperse(list, " ", fn {x, y} -> [num(x), ",", num(-y)] end)

  @commands %{16 => "waypoint", 17 => "loiter", 18 => "loiter turns", 19 => "loiter time", 20 => "return to launch", 21 => "land", 22 => "take-off", 31 => "loiter to altitude"}
  defp command(cmd), do: Map.get(@commands, cmd, "command #{cmd}")

  # --- the time line ---

  @lane_pad 8
  @row_h 22

  @doc false
  @spec timeline(map()) :: iodata()
  def timeline(model) do
    span = max(model.span_s, 1.0)
    x = fn t -> @label_w + max(0.0, min(t, span)) / span * (@width - @label_w - @right_pad) end
    lanes = Enum.map(model.vehicles, fn v -> {v, rows(v.tasks)} end)
    script_lane = if model.script || model.script_marks != [], do: 1, else: 0

    {body, height} =
      Enum.reduce(lanes, {[], 24 + script_lane * (@row_h + 2 * @lane_pad)}, fn {v, rows}, {acc, y} ->
        n = max(1, rows |> Enum.map(&elem(&1, 1)) |> Enum.max(fn -> 0 end) |> Kernel.+(1))
        h = n * @row_h + 2 * @lane_pad + 10
        {[acc, vehicle_lane(v, rows, y, h, x, model.script_marks)], y + h}
      end)

    [
      ~s(<svg id="timeline" class="timeline" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 #{@width} #{height + 4}">),
      axis(span, x, height),
      if(script_lane == 1, do: script_lane(model, x), else: []),
      body,
      "</svg>"
    ]
  end

  # Tasks of one vehicle in rows, so that overlapping ones do not hide each other.
  defp rows(tasks) do
    tasks
    |> Enum.sort_by(& &1.start)
    |> Enum.map_reduce([], fn t, ends ->
      case Enum.find_index(ends, &(&1 <= t.start)) do
        nil -> {{t, length(ends)}, ends ++ [t.stop]}
        i -> {{t, i}, List.replace_at(ends, i, t.stop)}
      end
    end)
    |> elem(0)
  end

  defp axis(span, x, height) do
    step = nice(span / 10)
    ticks = Stream.iterate(0.0, &(&1 + step)) |> Enum.take_while(&(&1 <= span))

    [
      ~s(<g class="axis">),
      Enum.map(ticks, fn t ->
        ~s(<line x1="#{num(x.(t))}" y1="18" x2="#{num(x.(t))}" y2="#{height}"/><text x="#{num(x.(t))}" y="13" text-anchor="middle">#{clock(t)}</text>)
      end),
      "</g>"
    ]
  end

  defp script_lane(model, x) do
    y = 24
    s = model.script

    [
      ~s(<g class="lane lane-script"><text class="lane-label" x="6" y="#{y + @lane_pad + 15}">script</text>),
      if(s && s.start,
        do:
          ~s(<rect class="script-bar result-#{esc(s.result)}" x="#{num(x.(s.start))}" y="#{y + @lane_pad}" width="#{num(max(1.0, x.(s.stop) - x.(s.start)))}" height="#{@row_h - 4}"><title>#{esc(s.name)}: #{esc(s.result)}#{reason(s.reason)}</title></rect>),
        else: []
      ),
      for({t, kind, text, nil} <- model.script_marks, do: mark(kind, x.(t), y + @lane_pad + @row_h - 2, text, t)),
      "</g>"
    ]
  end

  defp vehicle_lane(v, rows, y, h, x, script_marks) do
    [
      ~s(<g class="lane v-#{v.id}" data-vehicle="#{v.id}" style="--c:#{color(v.index)}">),
      ~s(<rect class="lane-bg" x="0" y="#{y}" width="#{@width}" height="#{h}"/>),
      ~s(<text class="lane-label" x="6" y="#{y + @lane_pad + 15}">vehicle #{v.id}</text>),
      Enum.map(rows, fn {t, row} -> task_bar(v, t, row, y, x) end),
      Enum.map(v.marks, fn {t, kind, text} -> mark(kind, x.(t), y + h - 6, text, t) end),
      for({t, kind, text, id} <- script_marks, id == v.id, do: mark(kind, x.(t), y + h - 6, text, t)),
      "</g>"
    ]
  end

  defp task_bar(v, t, row, y, x) do
    x0 = x.(t.start)
    w = max(2.0, x.(t.stop) - x0)
    top = y + @lane_pad + row * @row_h

    [
      ~s(<g class="task" data-vehicle="#{v.id}" data-name="#{esc(t.name)}" data-kind="#{esc(t.kind)}" data-result="#{esc(t.result)}">),
      ~s(<rect class="task-bar result-#{esc(t.result)}" x="#{num(x0)}" y="#{top}" width="#{num(w)}" height="#{@row_h - 4}"/>),
      ~s(<text class="task-label" x="#{num(x0 + 3)}" y="#{top + 13}">#{esc(fit(t.name, w))}</text>),
      ~s|<title>#{esc(t.kind)} “#{esc(t.name)}” on vehicle #{v.id}: #{esc(t.result)}#{reason(t.reason)} (#{clock(t.start)}–#{clock(t.stop)})</title></g>|
    ]
  end

  # The name as far as it fits in a bar `w` pixels wide (the hover shows it all).
  defp fit(name, w) do
    chars = trunc((w - 6) / 6.5)

    cond do
      chars < 3 -> ""
      String.length(name) <= chars -> name
      true -> String.slice(name, 0, chars - 1) <> "…"
    end
  end

  defp reason(nil), do: ""
  defp reason(r), do: " — #{esc(r)}"

  defp mark(kind, x, y, text, t) do
    shape =
      case kind do
        :condition -> ~s(<path d="M#{num(x)} #{y - 6} L#{num(x + 5)} #{y + 3} L#{num(x - 5)} #{y + 3} Z"/>)
        :lost -> ~s(<path d="M#{num(x - 4)} #{y - 4} L#{num(x + 4)} #{y + 4} M#{num(x + 4)} #{y - 4} L#{num(x - 4)} #{y + 4}"/>)
        :reconnected -> ~s(<circle cx="#{num(x)}" cy="#{y}" r="4"/>)
        :mode -> ~s(<path d="M#{num(x)} #{y - 5} L#{num(x + 4)} #{y} L#{num(x)} #{y + 5} L#{num(x - 4)} #{y} Z"/>)
        # A pause sign, and a play sign.
        :separation_hold -> ~s(<path d="M#{num(x - 3)} #{y - 5} V#{y + 5} M#{num(x + 3)} #{y - 5} V#{y + 5}"/>)
        :separation_clear -> ~s(<path d="M#{num(x - 3)} #{y - 5} L#{num(x + 5)} #{y} L#{num(x - 3)} #{y + 5} Z"/>)
        _ -> ~s(<circle cx="#{num(x)}" cy="#{y}" r="3"/>)
      end

    [~s(<g class="mark mark-#{kind}">), shape, "<title>", clock(t), " ", esc(text), "</title></g>"]
  end

  # --- plots ---

  @plot_h 170
  @plot_top 30
  @plot_bottom 12

  @doc false
  # `class`: what kind of plot it is besides its key's (`plot-KEY`): "sensor".
  @spec plot(map(), atom() | {:sensor, String.t()}, String.t(), String.t(), number() | nil, String.t() | nil) :: iodata()
  def plot(model, key, title, unit, fixed_max, class \\ nil) do
    span = max(model.span_s, 1.0)
    x = fn t -> @label_w + max(0.0, min(t, span)) / span * (@width - @label_w - @right_pad) end
    values = for v <- model.vehicles, {_, y} <- Map.get(v.series, key, []), do: y
    {lo, hi} = range(values, fixed_max)
    inner = @plot_h - @plot_top - @plot_bottom
    y = fn val -> @plot_top + inner - (val - lo) / (hi - lo) * inner end
    ticks = Stream.iterate(lo, &(&1 + nice((hi - lo) / 4))) |> Enum.take_while(&(&1 <= hi + 1.0e-9))

    [
      ~s(<svg class="plot #{class || "plot-#{key}"}" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 #{@width} #{@plot_h}">),
      ~s(<text class="plot-title" x="#{@label_w}" y="14">#{title}</text>),
      ~s(<g class="axis">),
      Enum.map(ticks, fn v ->
        ~s(<line x1="#{@label_w}" y1="#{num(y.(v))}" x2="#{@width - @right_pad}" y2="#{num(y.(v))}"/><text x="#{@label_w - 4}" y="#{num(y.(v) + 4)}" text-anchor="end">#{num(v, if(hi - lo < 5, do: 1, else: 0))} #{unit}</text>)
      end),
      "</g>",
      Enum.map(model.vehicles, fn v ->
        case Map.get(v.series, key, []) do
          [] ->
            []

          series ->
            [
              ~s(<polyline class="series v-#{v.id}" data-vehicle="#{v.id}" style="--c:#{color(v.index)}" points="),
              Enum.map_intersperse(series, " ", fn {t, val} -> [num(x.(t)), ",", num(y.(val))] end),
              ~s("><title>vehicle #{v.id}: #{title}</title></polyline>)
            ]
        end
      end),
      if(values == [], do: ~s(<text class="no-data" x="#{div(@width, 2)}" y="#{div(@plot_h, 2)}" text-anchor="middle">no data in the log</text>), else: []),
      "</svg>"
    ]
  end

  @doc false
  # The distance from each moment's closest pair, with the least separation's
  # line; the scale stops at ten times it (farther is apart, however far).
  @spec separation_plot(map()) :: iodata()
  def separation_plot(%{separation: %{series: series, least: least, limits: limits}} = model) do
    span = max(model.span_s, 1.0)
    x = fn t -> @label_w + max(0.0, min(t, span)) / span * (@width - @label_w - @right_pad) end
    top = nice(min(Enum.max(Enum.map(series, &elem(&1, 1)), fn -> limits.horizontal * 2 end), limits.horizontal * 10))
    inner = @plot_h - @plot_top - @plot_bottom
    y = fn val -> @plot_top + inner - min(val, top) / top * inner end
    ticks = Stream.iterate(0.0, &(&1 + nice(top / 4))) |> Enum.take_while(&(&1 <= top + 1.0e-9))
    title = "closest other vehicle across (of those within #{num(limits.vertical, 0)} m in height)"

    [
      ~s(<svg class="plot separation" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 #{@width} #{@plot_h}">),
      ~s(<text class="plot-title" x="#{@label_w}" y="14">#{title}),
      if(least, do: " — least #{num(least.across, 1)} m at #{clock(least.at_s)}, vehicles #{elem(least.pair, 0)} and #{elem(least.pair, 1)}", else: ""),
      "</text>",
      ~s(<g class="axis">),
      Enum.map(ticks, fn v ->
        ~s(<line x1="#{@label_w}" y1="#{num(y.(v))}" x2="#{@width - @right_pad}" y2="#{num(y.(v))}"/><text x="#{@label_w - 4}" y="#{num(y.(v) + 4)}" text-anchor="end">#{num(v, 0)} m</text>)
      end),
      "</g>",
      ~s(<line class="limit" x1="#{@label_w}" y1="#{num(y.(limits.horizontal))}" x2="#{@width - @right_pad}" y2="#{num(y.(limits.horizontal))}"><title>least separation: #{num(limits.horizontal, 0)} m across</title></line>),
      case series do
        [] -> ~s(<text class="no-data" x="#{div(@width, 2)}" y="#{div(@plot_h, 2)}" text-anchor="middle">never two vehicles in the air within #{num(limits.vertical, 0)} m in height</text>)
        _ -> [~s(<polyline class="series separation" points="), Enum.map_intersperse(series, " ", fn {t, val} -> [num(x.(t)), ",", num(y.(val))] end), ~s("/>)]
      end,
      "</svg>"
    ]
  end

  defp range(_values, max) when is_number(max), do: {0, max}
  defp range([], _), do: {0, 1}

  defp range(values, nil) do
    {lo, hi} = Enum.min_max(values)
    lo = min(0, lo)
    hi = if hi - lo < 1.0e-6, do: lo + 1, else: hi
    step = nice((hi - lo) / 4)
    {Float.floor(lo / step) * step, Float.ceil(hi / step) * step}
  end

  # 1, 2 or 5 times a power of ten, at least `x`.
  @doc false
  @spec nice(number()) :: float()
  def nice(x) when x <= 0, do: 1.0

  def nice(x) do
    p = :math.pow(10, Float.floor(:math.log10(x)))

    cond do
      x <= p -> p
      x <= 2 * p -> 2 * p
      x <= 5 * p -> 5 * p
      true -> 10 * p
    end
  end
end
