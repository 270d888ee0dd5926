defmodule Dolphin.Web.Live do
  @moduledoc false
  # The pure core of a live view: what the running fleet did so far, kept
  # bounded, as the flight report's own records (Report.FlightLog vehicles and
  # event maps as the events file has them), so the report's Model and HTML
  # draw it; plus the page's live parts: the vehicles' status now and a mark
  # on the map where each one is. Times are Dolphin.Clock milliseconds.

  alias Dolphin.Report.{FlightLog, HTML, Model}
  alias Dolphin.Vehicles.View

  # Positions kept per vehicle: past this, every other one is dropped (the
  # track keeps its shape over the whole run, at half the detail).
  @max_points 4_000
  # Battery, mode and arming samples kept per vehicle (the oldest dropped).
  @max_samples 2_000
  # Events kept: the oldest go beyond this.
  @max_events 5_000
  # Vehicles drawn on one page: a larger fleet is shown a page at a time (in
  # the order of their names, Dolphin.Vehicles.Id.sort/1, so that a vehicle stays on its page), with the
  # whole fleet counted above the rows. Drawing every vehicle of a fleet of
  # thousands four times a second would take the view's whole share of a
  # core for a page nobody can read.
  @page_size 50
  # Vehicles named in the counts line (the lost ones, the emptiest batteries).
  @named 5

  defstruct origin_ms: 0, started_at: nil, title: "Live run", tlog: nil, vehicles: %{}, views: %{}, counts: %{}, events: :queue.new(), n_events: 0, running: %{}

  @type t :: %__MODULE__{}

  @doc false
  # Options: :title, :tlog (the run's log, named on the page), :started_at
  # (the wall-clock time of origin_ms, a DateTime: Clock times are not).
  @spec new(integer(), keyword()) :: t()
  def new(origin_ms, opts \\ []) do
    %__MODULE__{origin_ms: origin_ms, started_at: opts[:started_at], title: Keyword.get(opts, :title, "Live run"), tlog: opts[:tlog]}
  end

  @doc false
  # A vehicle's new view, seen at clock time now_ms.
  @spec view(t(), View.t(), integer()) :: t()
  def view(live, %View{id: id} = view, now_ms) do
    ts = now_ms * 1000
    old = Map.get(live.views, id)
    v = Map.get(live.vehicles, id) || %FlightLog.Vehicle{id: id}
    # As a log's heartbeat would say it (the report's model reads both).
    v = %{v | type: view.mav_type, autopilot: view.autopilot}
    {v, added} = position(v, view, ts)
    v = if view.battery && (old == nil or pct(old.battery) != pct(view.battery)), do: %{v | battery: bounded([{ts, pct(view.battery)} | v.battery])}, else: v
    v = if view.mode && (old == nil or old.mode != view.mode), do: %{v | modes: bounded([{ts, view.mode} | v.modes])}, else: v
    v = if old == nil or old.armed? != view.armed?, do: %{v | arming: bounded([{ts, view.armed?} | v.arming])}, else: v
    v = readings(v, old, view)
    count = Map.get(live.counts, id, 0) + added
    {v, count} = if count > @max_points, do: {%{v | positions: thin(v.positions)}, div(count + 1, 2)}, else: {v, count}
    %{live | vehicles: Map.put(live.vehicles, id, v), views: Map.put(live.views, id, view), counts: Map.put(live.counts, id, count)}
  end

  # Each new sensor reading, at its own time (the report's plots draw them).
  defp readings(v, old, %View{sensors: sensors}) do
    Enum.reduce(sensors, v, fn {source, %{at: at, value: value}}, v ->
      case old && Map.get(old.sensors, source) do
        %{at: ^at} -> v
        _ -> %{v | sensors: Map.update(v.sensors, source, [{at * 1000, value}], &bounded([{at * 1000, value} | &1]))}
      end
    end)
  end

  defp pct(nil), do: nil
  defp pct(fraction), do: round(fraction * 100)

  defp bounded(samples), do: Enum.take(samples, @max_samples)

  # Newest first; the newest and the oldest stay.
  defp thin([newest | rest]) do
    {kept, last} = rest |> Enum.with_index() |> Enum.reduce({[], nil}, fn {p, i}, {acc, _} -> {if(rem(i, 2) == 1, do: [p | acc], else: acc), p} end)
    kept = Enum.reverse(kept)
    if last && List.last(kept) != last, do: [newest | kept ++ [last]], else: [newest | kept]
  end

  # A position as the log has it ({ts, lat e7, lon e7, height above home mm,
  # vx, vy cm/s}), when it moved: its velocity as reported, else the speed
  # since the last one (north).
  defp position(v, %View{position: nil}, _ts), do: {v, 0}

  defp position(v, %View{position: p} = view, ts) do
    lat = round(p.lat * 1.0e7)
    lon = round(p.lon * 1.0e7)
    rel = round((view.relative_altitude || 0.0) * 1000)

    case v.positions do
      [{_, ^lat, ^lon, ^rel, _, _} | _] ->
        {v, 0}

      _ when is_tuple(view.velocity) ->
        {vn, ve, _} = view.velocity
        {%{v | positions: [{ts, lat, lon, rel, round(vn * 100), round(ve * 100)} | v.positions]}, 1}

      [{ts0, lat0, lon0, _, _, _} | _] when ts > ts0 ->
        speed = Dolphin.Geo.distance(Dolphin.Geo.location(lat0 / 1.0e7, lon0 / 1.0e7, 0), Dolphin.Geo.location(p.lat, p.lon, 0)) / ((ts - ts0) / 1.0e6)
        {%{v | positions: [{ts, lat, lon, rel, round(speed * 100), 0} | v.positions]}, 1}

      _ ->
        {%{v | positions: [{ts, lat, lon, rel, 0, 0} | v.positions]}, 1}
    end
  end

  @doc false
  # One Dolphin.Events event.
  @spec event(t(), map()) :: t()
  def event(live, %{event: _, at_ms: _} = event) do
    e = event |> Dolphin.Events.to_json(live.origin_ms) |> :jiffy.decode([:return_maps, null_term: nil])
    {events, n} = if live.n_events >= @max_events, do: {:queue.drop(live.events), live.n_events}, else: {live.events, live.n_events + 1}
    %{live | events: :queue.in(e, events), n_events: n, running: running(live.running, e), vehicles: fenced(live.vehicles, e)}
  end

  # The fence a vehicle was given, as the log's fence and rally lists keep it (the map draws them).
  defp fenced(vehicles, %{"event" => "fence_applied", "vehicle" => id, "fence" => fence, "rally" => rally}) do
    v = Map.get(vehicles, id) || %FlightLog.Vehicle{id: id}
    zones = for {[command, x, y, param1], seq} <- Enum.with_index(fence), into: %{}, do: {seq, {command, x, y, 0.0, param1}}
    points = for {[x, y, z], seq} <- Enum.with_index(rally), into: %{}, do: {seq, {5100, x, y, z, 0.0}}
    Map.put(vehicles, id, %{v | fence: zones, rally: points})
  end

  defp fenced(vehicles, _e), do: vehicles

  # The platform task each vehicle flies now: vehicle => {task id, kind, name}.
  defp running(running, %{"event" => "task_started", "vehicle" => v} = e) when is_integer(v) or is_binary(v), do: Map.put(running, v, {e["task_id"], e["kind"], e["name"]})

  defp running(running, %{"event" => "task_finished", "task_id" => id}) do
    running |> Enum.reject(fn {_, {task, _, _}} -> task == id end) |> Map.new()
  end

  defp running(running, _e), do: running

  @doc false
  @spec vehicles(t()) :: [Dolphin.Vehicles.Id.t()]
  def vehicles(live), do: live.vehicles |> Map.keys() |> Dolphin.Vehicles.Id.sort()

  @doc false
  # How many pages the fleet fills (at least one).
  @spec pages(t()) :: pos_integer()
  def pages(live), do: max(1, div(map_size(live.vehicles) + @page_size - 1, @page_size))

  @doc false
  # The vehicles of page n (from 1; past the last, the last), in name order.
  @spec page_vehicles(t(), pos_integer()) :: [Dolphin.Vehicles.Id.t()]
  def page_vehicles(live, n), do: Enum.slice(vehicles(live), (page_number(live, n) - 1) * @page_size, @page_size)

  defp page_number(live, n), do: n |> max(1) |> min(pages(live))

  @doc false
  # Page n of the view (from 1; past the last, the last) at clock time now_ms
  # (a binary: its pieces are cut from it): the report drawn for the page's
  # vehicles, the events that concern them or no vehicle, and the whole
  # fleet counted.
  @spec page(t(), integer(), pos_integer()) :: binary()
  def page(live, now_ms, n \\ 1) do
    n = page_number(live, n)
    ids = page_vehicles(live, n)
    on_page = MapSet.new(ids)
    events = :queue.to_list(live.events)
    events = if map_size(live.vehicles) > @page_size, do: Enum.filter(events, &concerns?(&1, on_page)), else: events

    log = %FlightLog{
      vehicles: Map.new(ids, fn id -> {id, chronological(live.vehicles[id])} end),
      first_us: live.origin_ms * 1000,
      last_us: max(now_ms, live.origin_ms) * 1000,
      stats: nil
    }

    model = %{Model.build(log, events, {1.0, 0.0}) | started_at: live.started_at}
    info = %{title: live.title, tlog: live.tlog || "none", events: "live", events_skipped: 0}
    page = model |> HTML.page(info) |> IO.iodata_to_binary()

    page =
      page
      |> mark_positions(model)
      |> String.replace("</style>", css() <> "</style>", global: false)
      |> String.replace(~r{<p class="files">.*?</p>}s, files(live), global: false)

    [head, summary] = :binary.split(page, ~s(<section id="summary">))
    [tail, ""] = :binary.split(summary, "</body></html>\n")
    IO.iodata_to_binary([head, status(live, model, ids, n), ~s(<section id="summary">), tail, "<script>", js(), "</script></body></html>\n"])
  end

  defp concerns?(%{"vehicle" => v}, on_page) when v != nil, do: MapSet.member?(on_page, v)
  defp concerns?(%{"vehicles" => vs}, on_page) when is_list(vs), do: Enum.any?(vs, &MapSet.member?(on_page, &1))
  defp concerns?(_event, _on_page), do: true

  # Where the page's data comes from (the report's line names its files).
  defp files(live) do
    log = if live.tlog, do: [~s(; the telemetry log is written to <code title="), HTML.esc(Path.expand(live.tlog)), ~s(">), HTML.esc(Path.basename(live.tlog)), "</code>"], else: []
    IO.iodata_to_binary([~s(<p class="files">live from the running fleet: the vehicles' state and the run's events), log, "</p>"])
  end

  defp chronological(v) do
    %{
      v
      | positions: Enum.reverse(v.positions),
        battery: Enum.reverse(v.battery),
        modes: Enum.reverse(v.modes),
        arming: Enum.reverse(v.arming),
        sensors: Map.new(v.sensors, fn {source, list} -> {source, Enum.reverse(list)} end)
    }
  end

  @doc false
  # The parts of a page that change as the run goes on, {id, inner html}: the
  # line under the heading, the legend and each section.
  @spec pieces(binary()) :: [{String.t(), binary()}]
  def pieces(page) do
    [when_] = Regex.run(~r{<p class="when">(.*?)</p>}s, page, capture: :all_but_first)
    [legend] = Regex.run(~r{<nav class="legend">(.*?)</nav>}s, page, capture: :all_but_first)
    sections = for [id, html] <- Regex.scan(~r{<section id="([\w-]+)">(.*?)</section>}s, page, capture: :all_but_first), do: {id, html}
    [{"when", when_}, {"legend", legend} | sections]
  end

  # A dot on the map where each vehicle is now (the end of its track), sized
  # as the map's other marks.
  defp mark_positions(page, model) do
    case Regex.run(~r{<svg id="map" class="map"[^>]*viewBox="(\S+) (\S+) (\S+) (\S+)"}, page, capture: :all_but_first) do
      [_, _, w, h] ->
        r = max(String.to_float(w), String.to_float(h)) / 110

        dots =
          for %{track: [_ | _] = track} = v <- model.vehicles do
            {x, y} = List.last(track)

            ~s(<circle class="now v-#{v.id}" data-vehicle="#{v.id}" cx="#{HTML.num(x, 2)}" cy="#{HTML.num(-y, 2)}" r="#{HTML.num(r, 2)}" style="--c:#{HTML.color(v.index)}"><title>vehicle #{v.id} now</title></circle>)
          end

        [head, tail] = :binary.split(page, ~s(<g class="scale-bar"))
        IO.iodata_to_binary([head, dots, ~s(<g class="scale-bar"), tail])

      nil ->
        page
    end
  end

  # What each vehicle of the page is doing now: one row per vehicle, under
  # the whole fleet's counts and, when there are several, the pages.
  defp status(live, model, ids, n) do
    index = Map.new(model.vehicles, &{&1.id, &1.index})

    [
      ~s(<section id="live-status"><h2>Now <span class="live-state" id="live-state">live</span></h2>),
      counts(live),
      pager(live, ids, n),
      ~s(<table class="summary"><thead><tr><th>vehicle</th><th>link</th><th>mode</th><th>armed</th><th>battery</th><th>height</th><th>position</th><th>mission</th><th>task</th>#{if model.sensors != [], do: "<th>sensors</th>"}</tr></thead><tbody>),
      for id <- ids, view = live.views[id], view != nil do
        {lat, lon} = if view.position, do: {HTML.num(view.position.lat, 7), HTML.num(view.position.lon, 7)}, else: {"", ""}

        [
          ~s(<tr class="v-#{id} live-vehicle" data-vehicle="#{id}" data-lat="#{lat}" data-lon="#{lon}" style="--c:#{HTML.color(Map.get(index, id, 0))}">),
          ~s(<td><span class="swatch"></span>#{id}</td><td>#{if view.connected?, do: "connected", else: "<b>lost</b>"}</td>),
          "<td>#{HTML.esc(view.mode && view.mode |> Atom.to_string() |> String.upcase())}</td><td>#{if view.armed?, do: "yes", else: "no"}</td>",
          "<td>#{if view.battery, do: "#{pct(view.battery)} %", else: "—"}</td>",
          "<td>#{if view.relative_altitude, do: "#{HTML.num(view.relative_altitude, 1)} m", else: "—"}</td>",
          "<td>#{if lat != "", do: "#{lat}, #{lon}", else: "—"}</td>",
          "<td>#{case view.mission_progress do
            {reached, total} -> "#{reached}/#{total}"
            nil -> "—"
          end}</td>",
          "<td>#{case live.running[id] do
            {task, kind, name} -> HTML.esc("#{task} #{kind} “#{name}”")
            nil -> "—"
          end}</td>",
          if(model.sensors != [], do: ["<td class=\"sensors\">", sensors_now(view, model.sensors), "</td>"], else: []),
          "</tr>"
        ]
      end,
      "</tbody></table></section>\n"
    ]
  end

  # The whole fleet in one line: how many are connected, lost, armed and
  # flying a task; which are lost and which have the emptiest batteries.
  defp counts(%{views: views}) when map_size(views) == 0, do: []

  defp counts(live) do
    views = Map.values(live.views)
    lost = views |> Enum.reject(& &1.connected?) |> Enum.map(& &1.id) |> Enum.sort()
    armed = Enum.count(views, & &1.armed?)
    emptiest = views |> Enum.filter(& &1.battery) |> Enum.sort_by(&{&1.battery, &1.id}) |> Enum.take(@named)

    [
      ~s(<p class="fleet-counts">),
      "#{count(length(views), "vehicle")}: #{length(views) - length(lost)} connected, ",
      if(lost == [], do: "none lost", else: ["<b>#{length(lost)} lost</b> (", HTML.esc(names(lost)), ")"]),
      "; #{armed} armed; #{map_size(live.running)} flying a task",
      if(emptiest == [], do: [], else: ["; emptiest batteries: ", HTML.esc(Enum.map_join(emptiest, ", ", &"#{&1.id} #{pct(&1.battery)} %"))]),
      "</p>"
    ]
  end

  defp names(ids) when length(ids) > @named, do: Enum.map_join(Enum.take(ids, @named), ", ") <> " and #{length(ids) - @named} more"
  defp names(ids), do: Enum.join(ids, ", ")

  defp count(1, noun), do: "1 #{noun}"
  defp count(n, noun), do: "#{n} #{noun}s"

  # Which vehicles this page shows and links to the pages beside it (?page=N).
  defp pager(live, ids, n) do
    case pages(live) do
      1 ->
        []

      pages ->
        first = (n - 1) * @page_size + 1
        previous = if n > 1, do: ~s(<a href="?page=#{n - 1}">‹ page #{n - 1}</a> · ), else: ""
        next = if n < pages, do: ~s( · <a href="?page=#{n + 1}">page #{n + 1} ›</a>), else: ""

        ~s[<nav class="pager">#{previous}vehicles #{first}–#{first + length(ids) - 1} of #{map_size(live.vehicles)} (#{HTML.esc(hd(ids))} to #{HTML.esc(List.last(ids))}), page #{n} of #{pages}, on the map and in every section below#{next}</nav>]
    end
  end

  # The latest reading of each sensor the run declared, on one vehicle.
  defp sensors_now(view, sensors) do
    Enum.map_join(sensors, ", ", fn s ->
      case Map.get(view.sensors, s.source) do
        %{value: raw, stale: []} -> HTML.esc("#{s.name} #{HTML.num(raw * s.scale + s.offset, 2)}#{if s.unit, do: " #{s.unit}"}")
        %{value: raw} -> HTML.esc("#{s.name} #{HTML.num(raw * s.scale + s.offset, 2)} (stale)")
        nil -> HTML.esc("#{s.name} —")
      end
    end)
  end

  # The page follows the run: it listens to /events (Server-Sent Events) and
  # puts each piece it is sent in place; vehicles hidden in the legend stay
  # hidden. A lost stream is retried by the browser; the first frame of each
  # stream is the whole state. With ?frames=N it stops after N frames: a
  # snapshot that went through the live path, which a headless browser can
  # wait for (an open stream keeps its page loading for ever).
  defp js do
    """
    (function(){
      var hidden = {};
      function hide(){
        document.querySelectorAll('.legend input').forEach(function(box){ box.checked = !hidden[box.dataset.vehicle]; });
        Object.keys(hidden).forEach(function(id){
          document.querySelectorAll('.v-' + CSS.escape(String(id))).forEach(function(el){ if(el.tagName !== 'LABEL') el.classList.add('hidden'); });
        });
      }
      document.addEventListener('change', function(ev){
        var box = ev.target;
        if(!box.dataset || !box.dataset.vehicle) return;
        if(box.checked) delete hidden[box.dataset.vehicle]; else hidden[box.dataset.vehicle] = true;
        document.querySelectorAll('.v-' + CSS.escape(box.dataset.vehicle)).forEach(function(el){
          if(el.tagName !== 'LABEL') el.classList.toggle('hidden', !box.checked);
        });
      });
      function place(id, html){
        var el = id === 'when' ? document.querySelector('p.when') : id === 'legend' ? document.querySelector('nav.legend') : document.getElementById(id);
        if(el) el.innerHTML = html;
      }
      if(!window.EventSource) return;
      var limit = +(new URLSearchParams(location.search).get('frames') || 0);
      var page = new URLSearchParams(location.search).get('page');
      var source = new EventSource('events' + (page ? '?page=' + encodeURIComponent(page) : ''));
      source.addEventListener('frame', function(ev){
        var frame = JSON.parse(ev.data);
        frame.pieces.forEach(function(p){ place(p[0], p[1]); });
        hide();
        var count = (+document.body.dataset.frames || 0) + 1;
        document.body.dataset.frames = count;
        var s = document.getElementById('live-state');
        if(limit && count >= limit){
          source.close();
          if(s){ s.textContent = 'snapshot'; s.className = 'live-state ended'; }
        } else if(s){ s.textContent = 'live'; s.className = 'live-state'; }
      });
      source.addEventListener('end', function(){
        source.close();
        var s = document.getElementById('live-state');
        if(s){ s.textContent = 'run ended'; s.className = 'live-state ended'; }
      });
      source.onerror = function(){
        var s = document.getElementById('live-state');
        if(s && source.readyState !== 2){ s.textContent = 'reconnecting'; s.className = 'live-state lost'; }
      };
    })();
    """
  end

  # The page's own styles for its live parts (inserted in its <style>).
  defp css do
    ".live-state{font-size:12px;font-weight:normal;color:#fff;background:#2e9d4d;border-radius:3px;padding:1px 6px;margin-left:8px}" <>
      ".live-state.lost{background:#e0a030}.live-state.ended{background:#777}" <>
      "circle.now{fill:var(--c);stroke:#000;stroke-width:1.5;vector-effect:non-scaling-stroke}" <>
      ".fleet-counts{margin:4px 0}.pager{margin:4px 0 8px}"
  end
end
