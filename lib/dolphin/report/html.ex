defmodule Dolphin.Report.HTML do
  @moduledoc false
  # The page of a flight report: one self-contained HTML file (inline CSS, SVG
  # and a few lines of script; nothing fetched), from a Report.Model.

  alias Dolphin.Report.SVG

  # Tracks coloured per vehicle: distinct hues that read on white.
  @palette ~w(#1f77b4 #d62728 #2ca02c #9467bd #ff7f0e #17becf #8c564b #e377c2 #7f7f7f #bcbd22)

  @doc false
  @spec page(map(), map()) :: iodata()
  def page(model, info) do
    [
      "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">",
      "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">",
      "<title>",
      esc(info.title),
      " — ",
      esc(Path.basename(info.tlog)),
      "</title>",
      "<style>",
      css(),
      "</style></head>\n<body data-vehicles=\"#{length(model.vehicles)}\">",
      "<header><h1>",
      esc(info.title),
      "</h1>",
      "<p class=\"files\">telemetry log ",
      file(info.tlog),
      if(info.events, do: ["; events ", file(info.events)], else: "; no events file: the time line shows no tasks"),
      "</p><p class=\"when\">",
      if(model.started_at, do: ["started ", model.started_at |> DateTime.truncate(:second) |> DateTime.to_string(), " · "], else: []),
      "#{clock(model.span_s)} of clock time",
      if(abs(model.speedup - 1) > 0.05, do: " (flown #{num(model.speedup, 1)}× faster than real time)", else: ""),
      "</p>",
      notes(model, info),
      "</header>\n",
      legend(model),
      "<section id=\"summary\"><h2>Summary</h2>",
      script_result(model.script),
      summary(model),
      "</section>\n",
      "<section id=\"map-section\"><h2>Map</h2><p class=\"hint\">Solid: flown; dashed: planned (each mission uploaded); ▲ take-off, ▼ landing, ■ home, small squares: photos, circles: where each task started (hollow) and ended (filled, coloured by result); the fence uploaded: green dashes its inclusion zones, red shading its no-fly zones, R its rally points. Grid in metres, north up. Hover for details; ◎ where a sensor read what the script waited for.</p>",
      SVG.map(model),
      "</section>\n",
      "<section id=\"timeline-section\"><h2>Time line</h2><p class=\"hint\">A bar per task, coloured by how it ended: <span class=\"key result-done\">done</span> <span class=\"key result-stopped\">stopped</span> <span class=\"key result-failed\">failed</span> <span class=\"key result-unfinished\">unfinished</span>. Marks: ▲ condition met, ◆ mode change, ✕ lost, ○ reconnected, ‖ held apart from another vehicle, ▶ going on, • message. Hover for the reason.</p>",
      SVG.timeline(model),
      "</section>\n",
      "<section id=\"plots\"><h2>Over time</h2>",
      SVG.plot(model, :battery, "battery", "%", 100),
      SVG.plot(model, :height, "height above home", "m", nil),
      SVG.plot(model, :speed, "ground speed", "m/s", nil),
      SVG.plot(model, :link, "link quality (frames received)", "%", 100),
      if(length(model.vehicles) > 1, do: SVG.separation_plot(model), else: []),
      Enum.map(model.sensors, &SVG.plot(model, {:sensor, &1.name}, "sensor #{&1.name}", &1.unit || "", nil, "sensor")),
      "</section>\n<script>",
      js(),
      "</script></body></html>\n"
    ]
  end

  # A file by its name, its whole path on hover.
  defp file(path), do: [~s(<code title="), esc(Path.expand(path)), ~s(">), esc(Path.basename(path)), "</code>"]

  defp notes(model, info) do
    skipped =
      case model.stats do
        %{bytes_skipped: 0} ->
          []

        nil ->
          []

        stats ->
          why =
            [:truncated, :bad_crc, :bad_signature, :bad_incompat_flags, :unknown_id, :old_timestamp, :unsigned]
            |> Enum.filter(&(Map.get(stats, &1, 0) > 0))
            |> Enum.map_join(", ", &"#{&1 |> to_string() |> String.replace("_", " ")} #{Map.get(stats, &1)}")

          ["<li>The telemetry log is damaged: #{stats.bytes_skipped} of #{stats.bytes} bytes were skipped (#{why}); this report shows the #{stats.frames} frames that could be read.</li>"]
      end

    events = if info.events_skipped > 0, do: ["<li>#{info.events_skipped} line(s) of the events file could not be read and were skipped.</li>"], else: []

    runs =
      case Map.get(info, :runs) do
        {n, run} when n > 1 ->
          [
            "<li id=\"runs\">The telemetry log holds #{n} runs (the vehicles' clocks started again after the ground station had stopped recording): this report shows run #{run} of #{n} alone",
            if(run == n, do: ", the last", else: ""),
            " (<code>mix dolphin.report --run N</code> shows another).</li>"
          ]

        _ ->
          []
      end

    case runs ++ skipped ++ events do
      [] -> []
      items -> ["<ul class=\"notes\" id=\"skipped\">", items, "</ul>"]
    end
  end

  defp legend(model) do
    [
      "<nav class=\"legend\">",
      Enum.map(model.vehicles, fn v ->
        ~s(<label class="v-#{v.id}" style="--c:#{color(v.index)}"><input type="checkbox" checked data-vehicle="#{v.id}"><span class="swatch"></span>vehicle #{v.id}</label>)
      end),
      "</nav>"
    ]
  end

  defp script_result(nil), do: []

  defp script_result(s) do
    [
      ~s(<p class="script">Script <code title="#{esc(s.name)}">#{esc(Path.basename(s.name || "?"))}</code>: <span class="result result-#{esc(s.result)}" id="script-result">#{esc(s.result)}</span>),
      if(s.reason, do: [" — ", esc(s.reason)], else: []),
      "</p>"
    ]
  end

  defp summary(model) do
    [
      "<table class=\"summary\"><thead><tr><th>vehicle</th><th>kind</th><th>flight time</th><th>distance</th><th>items reached</th><th>photos</th><th>lowest battery</th><th>failures</th></tr></thead><tbody>",
      Enum.map(model.vehicles, fn v ->
        s = v.summary

        [
          ~s(<tr class="v-#{v.id}" data-vehicle="#{v.id}" style="--c:#{color(v.index)}"><td><span class="swatch"></span>#{v.id}</td>),
          "<td>#{esc(v.kind || "—")}</td><td>#{clock(s.flight_s)}</td><td>#{distance(s.distance_m)}</td><td>#{s.reached}</td><td>#{s.photos}</td>",
          "<td>#{if s.lowest_battery, do: "#{s.lowest_battery} %", else: "—"}</td><td class=\"failures\">",
          case s.failures do
            [] -> "none"
            fs -> ["<ul>", Enum.map(fs, fn {name, why} -> ["<li><b>", esc(name), "</b>", if(why, do: [": ", esc(why)], else: []), "</li>"] end), "</ul>"]
          end,
          "</td></tr>"
        ]
      end),
      "</tbody></table>"
    ]
  end

  defp distance(m) when m >= 1000, do: "#{num(m / 1000, 2)} km"
  defp distance(m), do: "#{num(m, 0)} m"

  # --- helpers shared with Report.SVG ---

  @doc false
  @spec esc(term()) :: String.t()
  def esc(nil), do: ""

  def esc(text) when is_binary(text) do
    text
    |> String.replace("&", "&amp;")
    |> String.replace("<", "&lt;")
    |> String.replace(">", "&gt;")
    |> String.replace("\"", "&quot;")
  end

  def esc(other), do: other |> to_string() |> esc()

  @doc false
  @spec num(number(), non_neg_integer()) :: String.t()
  def num(x, decimals \\ 1)
  def num(x, 0), do: x |> round() |> Integer.to_string()
  def num(x, decimals) when is_integer(x), do: num(x * 1.0, decimals)
  def num(x, decimals), do: :erlang.float_to_binary(x, decimals: decimals)

  @doc false
  @spec color(non_neg_integer()) :: String.t()
  def color(index), do: Enum.at(@palette, rem(index, length(@palette)))

  @doc false
  # Clock seconds as m:ss or h:mm:ss.
  @spec clock(number() | nil) :: String.t()
  def clock(nil), do: "?"

  def clock(seconds) do
    s = max(0, round(seconds))
    {h, m, sec} = {div(s, 3600), div(rem(s, 3600), 60), rem(s, 60)}
    pad = &String.pad_leading(Integer.to_string(&1), 2, "0")
    if h > 0, do: "#{h}:#{pad.(m)}:#{pad.(sec)}", else: "#{m}:#{pad.(sec)}"
  end

  defp css do
    """
    body{font:14px/1.4 system-ui,-apple-system,"DejaVu Sans",sans-serif;margin:0 auto;max-width:1240px;padding:12px 20px;color:#222;background:#fff}
    h1{font-size:22px;margin:4px 0}h2{font-size:17px;margin:18px 0 6px;border-bottom:1px solid #ddd}
    code{font-size:12px;background:#f4f4f4;padding:1px 3px}.files,.when,.hint{color:#555;margin:2px 0}.hint{font-size:12px}
    .notes{background:#fff4e0;border:1px solid #f0c070;padding:6px 24px}
    .legend{position:sticky;top:0;background:#fffe;padding:6px 0;z-index:1;border-bottom:1px solid #eee}
    .legend label{margin-right:14px;cursor:pointer}
    .swatch{display:inline-block;width:12px;height:12px;border-radius:2px;background:var(--c);margin:0 5px -1px 2px}
    table.summary{border-collapse:collapse;width:100%}table.summary th,table.summary td{border-bottom:1px solid #eee;padding:4px 8px;text-align:left;vertical-align:top}
    table.summary ul{margin:0;padding-left:16px}
    .result{font-weight:bold}.result-done{color:#1a7f37}.result-stopped{color:#b7791f}.result-failed,.result-halted{color:#c62828}.result-unfinished{color:#666}
    .key{padding:0 6px;border-radius:3px;color:#fff!important}.key.result-done{background:#2e9d4d}.key.result-stopped{background:#e0a030}.key.result-failed{background:#d64545}.key.result-unfinished{background:#999}
    svg{display:block;width:100%;font-family:inherit}
    svg.map{height:auto;aspect-ratio:1.6;border:1px solid #ddd;background:#fcfcfa}
    .grid line{stroke:#e3e3e3;stroke-width:1;vector-effect:non-scaling-stroke}
    .scale-bar rect,.north-arrow path{fill:#333}.scale-bar text,.north-arrow text{fill:#333}
    .vehicle .flown{fill:none;stroke:var(--c);stroke-width:2.2;stroke-linejoin:round;vector-effect:non-scaling-stroke}
    .vehicle .planned{fill:none;stroke:var(--c);stroke-width:1.3;stroke-dasharray:6 4;opacity:.7;vector-effect:non-scaling-stroke}
    .zone.inclusion{fill:none;stroke:#2a8a3a;stroke-width:1.5;stroke-dasharray:10 5;vector-effect:non-scaling-stroke}
    .zone.exclusion{fill:#c0392b;fill-opacity:.15;stroke:#c0392b;stroke-width:1.2;vector-effect:non-scaling-stroke}
    .rally{fill:#2a8a3a;font-weight:bold}
    .vehicle .item{fill:#fff;stroke:var(--c);stroke-width:1;vector-effect:non-scaling-stroke}
    .vehicle .photo{fill:#fff;stroke:#333;stroke-width:1;vector-effect:non-scaling-stroke}
    .vehicle .takeoff,.vehicle .landing{fill:var(--c);stroke:#000;stroke-width:1;vector-effect:non-scaling-stroke}
    .vehicle .home rect{fill:#fff;stroke:#000;stroke-width:1.5;vector-effect:non-scaling-stroke}.vehicle .home text{fill:#000}
    .vehicle .task-start{fill:#fff;stroke:var(--c);stroke-width:2;vector-effect:non-scaling-stroke}
    .vehicle .task-end{stroke:#000;stroke-width:1;vector-effect:non-scaling-stroke}
    .task-end.result-done{fill:#2e9d4d}.task-end.result-stopped{fill:#e0a030}.task-end.result-failed{fill:#d64545}.task-end.result-unfinished{fill:#999}
    svg.timeline text,svg.plot text{font-size:11px;fill:#444}.plot-title{font-weight:bold;font-size:12px!important}
    .axis line{stroke:#eee}.lane-bg{fill:#fafafa;stroke:#eee}.lane-label{font-weight:bold;fill:var(--c,#222)!important}
    .task-bar{stroke:#0003}.task-bar.result-done{fill:#2e9d4d}.task-bar.result-stopped{fill:#e0a030}.task-bar.result-failed{fill:#d64545}.task-bar.result-unfinished{fill:#999}
    .script-bar{fill:#ccc}.script-bar.result-done{fill:#9fd5ad}.script-bar.result-stopped{fill:#f3d28f}.script-bar.result-failed,.script-bar.result-halted{fill:#eda0a0}
    .task-label{fill:#fff!important;pointer-events:none}
    .mark path,.mark circle{stroke:#333;fill:#333;stroke-width:1.2}.mark-lost path{stroke:#c62828;stroke-width:2}.mark-reconnected circle{fill:none;stroke:#1a7f37;stroke-width:2}
    .mark-condition path{fill:#6a3d9a;stroke:none}.mark-mode path{fill:#888;stroke:none}.mark-text circle,.mark-message circle{fill:#1f77b4;stroke:none}
    .series{fill:none;stroke:var(--c);stroke-width:1.5}
    .mark-separation_hold path{stroke:#c62828;stroke-width:2.5;fill:none}.mark-separation_clear path{fill:#1a7f37;stroke:none}
    .detection{fill:none;stroke:#e65100;stroke-width:2.5;vector-effect:non-scaling-stroke}.detection-dot{fill:#e65100}
    svg.separation .series{stroke:#333}svg.separation .limit{stroke:#c62828;stroke-width:1.5;stroke-dasharray:6 4}
    .hidden{display:none}
    g.vehicle:hover .flown,.series:hover{stroke-width:4}
    """
  end

  # Toggling a vehicle hides it everywhere. Once drawn, every flown track
  # records its drawn length and on-screen box, and the body says it is
  # ready: what a browser test reads back from the page.
  defp js do
    """
    (function(){
      document.querySelectorAll('.legend input').forEach(function(box){
        box.addEventListener('change', function(){
          document.querySelectorAll('.v-' + CSS.escape(box.dataset.vehicle)).forEach(function(el){
            if(el.tagName !== 'LABEL') el.classList.toggle('hidden', !box.checked);
          });
        });
      });
      var map = document.getElementById('map');
      var frame = map.getBoundingClientRect();
      document.querySelectorAll('#map .flown').forEach(function(path){
        var box = path.getBoundingClientRect();
        path.dataset.drawnLength = Math.round(path.getTotalLength());
        path.dataset.onScreen = (box.width + box.height > 0 && box.left >= frame.left - 1 && box.right <= frame.right + 1 &&
          box.top >= frame.top - 1 && box.bottom <= frame.bottom + 1) ? 'yes' : 'no';
      });
      document.querySelectorAll('#timeline .task-bar').forEach(function(bar){
        bar.parentNode.dataset.drawnWidth = Math.round(bar.getBoundingClientRect().width);
      });
      document.body.dataset.ready = 'yes';
    })();
    """
  end
end
