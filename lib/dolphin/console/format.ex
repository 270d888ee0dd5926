defmodule Dolphin.Console.Format do
  @moduledoc false
  # Pure text of the console (Dolphin.Console): tables, the task tree, the
  # watch ticker (event lines are Dolphin.EventText's). Every function takes plain
  # data and returns a string (no trailing newline), so all of it is tested
  # without IEx.

  alias Dolphin.Geo.Location

  # --- generic -----------------------------------------------------------------

  @doc false
  # A table: a header row, then one row per entry; columns padded to their
  # widest cell, those listed in `right` aligned right.
  @spec table([String.t()], [[String.t()]], [non_neg_integer()]) :: String.t()
  def table(headers, rows, right \\ []) do
    all = [headers | rows]
    widths = for i <- 0..(length(headers) - 1), do: all |> Enum.map(&String.length(Enum.at(&1, i, ""))) |> Enum.max()

    all
    |> Enum.map(fn row ->
      row
      |> Enum.zip(widths)
      |> Enum.with_index()
      |> Enum.map_join("  ", fn {{cell, w}, i} -> if i in right, do: String.pad_leading(cell, w), else: String.pad_trailing(cell, w) end)
      |> String.trim_trailing()
    end)
    |> Enum.join("\n")
  end

  @doc false
  # A tree of nodes %{text, state, children} as lines with branch glyphs; the
  # states line up in one column after the widest text.
  @spec tree([map()]) :: String.t()
  def tree(nodes) do
    lines = flatten(nodes, "", true)
    width = lines |> Enum.map(fn {prefix, text, _} -> String.length(prefix <> text) end) |> Enum.max(fn -> 0 end)

    Enum.map_join(lines, "\n", fn
      {prefix, text, nil} -> prefix <> text
      {prefix, text, state} -> String.pad_trailing(prefix <> text, width) <> "  " <> state
    end)
  end

  defp flatten(nodes, indent, top?) do
    count = length(nodes)

    nodes
    |> Enum.with_index(1)
    |> Enum.flat_map(fn {node, i} ->
      last? = i == count

      {branch, further} =
        cond do
          top? -> {"", ""}
          last? -> {"└─ ", "   "}
          true -> {"├─ ", "│  "}
        end

      [{indent <> branch, node.text, Map.get(node, :state)} | flatten(Map.get(node, :children, []), indent <> further, false)]
    end)
  end

  @doc false
  # Seconds with one decimal: "12.3 s".
  @spec seconds(number()) :: String.t()
  def seconds(ms), do: :erlang.float_to_binary(ms / 1000, decimals: 1) <> " s"

  @doc false
  # A duration for humans: "850 ms", "12.3 s", "4m 05s", "1h 02m".
  @spec duration(number()) :: String.t()
  def duration(ms) when ms < 1_000, do: "#{round(ms)} ms"
  def duration(ms) when ms < 60_000, do: seconds(ms)

  def duration(ms) when ms < 3_600_000 do
    s = div(round(ms), 1000)
    "#{div(s, 60)}m #{String.pad_leading(Integer.to_string(rem(s, 60)), 2, "0")}s"
  end

  def duration(ms) do
    m = div(round(ms), 60_000)
    "#{div(m, 60)}h #{String.pad_leading(Integer.to_string(rem(m, 60)), 2, "0")}m"
  end

  @doc false
  # A mode as ArduPilot writes it: GUIDED, ALT_HOLD; "-" when unknown.
  @spec mode(term()) :: String.t()
  def mode(nil), do: "-"
  def mode({:custom, n}), do: "custom #{n}"
  def mode(mode) when is_atom(mode), do: mode |> Atom.to_string() |> String.upcase()
  def mode(other), do: to_string(other)

  @doc false
  @spec battery(number() | nil) :: String.t()
  def battery(nil), do: "-"
  def battery(fraction), do: "#{round(fraction * 100)} %"

  @doc false
  # A ten-cell bar of a fraction: "[#######   ]".
  @spec bar(number() | nil) :: String.t()
  def bar(nil), do: "[          ]"

  def bar(fraction) do
    n = fraction |> max(0) |> min(1) |> Kernel.*(10) |> round()
    "[" <> String.duplicate("#", n) <> String.duplicate(" ", 10 - n) <> "]"
  end

  @doc false
  @spec position(number() | nil, number() | nil) :: String.t()
  def position(lat, lon) when is_number(lat) and is_number(lon), do: "#{deg(lat)}, #{deg(lon)}"
  def position(_, _), do: "-"

  defp deg(x), do: :erlang.float_to_binary(x / 1, decimals: 6)

  @doc false
  @spec metres(number() | nil) :: String.t()
  def metres(nil), do: "-"
  def metres(m), do: :erlang.float_to_binary(m / 1, decimals: 1) <> " m"

  # --- vehicles ------------------------------------------------------------------

  @doc false
  # The vehicles() table. Each row: %{id, type, airframe, mode, armed, battery, lat, lon,
  # alt (above home), link: nil | %{received, lost}, seen_ms (since the last
  # frame, or nil), lost?, activity}, and optionally paths (those of
  # Dolphin.Vehicles.paths/1, each with seen_ms): a vehicle heard on more than
  # one link gets a line per path under the table.
  @spec vehicles([map()]) :: String.t()
  def vehicles([]), do: "no vehicles known yet (a link may still be waiting for their first heartbeat)"

  def vehicles(rows) do
    paths = for r <- rows, length(Map.get(r, :paths, [])) > 1, do: paths(r.id, r.paths)
    Enum.join([vehicles_table(rows) | paths], "\n")
  end

  @doc """
  The line under a page of a large fleet's table.

      iex> Dolphin.Console.Format.page_line(2, 20, 50, 1000)
      "vehicles 51-100 of 1000 (page 2 of 20): vehicles(3) for the next, vehicles(:all) for every one"
      iex> Dolphin.Console.Format.page_line(3, 3, 50, 120)
      "vehicles 101-120 of 120 (page 3 of 3): vehicles(:all) for every one"
  """
  @spec page_line(pos_integer(), pos_integer(), pos_integer(), non_neg_integer()) :: String.t()
  def page_line(page, pages, rows, count) do
    next = if page < pages, do: "vehicles(#{page + 1}) for the next, ", else: ""
    "vehicles #{(page - 1) * rows + 1}-#{min(page * rows, count)} of #{count} (page #{page} of #{pages}): #{next}vehicles(:all) for every one"
  end

  @doc false
  # A vehicle's paths, one line each, the one in use marked:
  # "vehicle 1 paths:\n  * udpin:0.0.0.0:14550  active   loss 0 %, 12 ms, 1520 frames, heard 40 ms ago".
  @spec paths(integer(), [map()]) :: String.t()
  def paths(id, paths) do
    rows =
      Enum.map(paths, fn p ->
        figures = [if(p.loss, do: "loss #{round(p.loss * 100)} %", else: "loss ?"), if(p.rtt_ms, do: "#{round(p.rtt_ms)} ms", else: "? ms"), "#{p.frames} frames"]
        ["  " <> if(p.in_use?, do: "*", else: " "), Dolphin.Vehicles.Paths.via_text(p.via), path_state(p), Enum.join(figures, ", "), "heard " <> seen(p.seen_ms, false)]
      end)

    "vehicle #{id} paths:\n" <> pad_columns(rows)
  end

  # A path not (yet) known to be the vehicle's says so (Dolphin.Vehicles.Paths,
  # "Another vehicle with the same system id").
  defp path_state(%{identity: :pending}), do: "identifying"
  defp path_state(%{identity: :refused, uid: uid}), do: "another vehicle (unique id #{uid})"
  defp path_state(p), do: Atom.to_string(p.state)

  # Columns lined up (each cell padded to its column's widest).
  defp pad_columns(rows) do
    widths = rows |> Enum.zip() |> Enum.map(fn column -> column |> Tuple.to_list() |> Enum.map(&String.length/1) |> Enum.max() end)
    Enum.map_join(rows, "\n", fn row -> row |> Enum.zip(widths) |> Enum.map_join("  ", fn {c, w} -> String.pad_trailing(c, w) end) |> String.trim_trailing() end)
  end

  defp vehicles_table(rows) do
    table(
      ["ID", "TYPE", "AIRFRAME", "MODE", "ARMED", "BATTERY", "POSITION", "ALT", "LINK", "SEEN", "TASK"],
      Enum.map(rows, fn r ->
        [
          Dolphin.Fleet.VehicleSet.format(r.id),
          r.type || "-",
          r.airframe || "-",
          mode(r.mode),
          if(r.armed, do: "yes", else: "no"),
          battery(r.battery),
          position(r.lat, r.lon),
          metres(r.alt),
          link(r.link),
          seen(r.seen_ms, r.lost?),
          r.activity || "-"
        ]
      end),
      [0, 5, 7]
    )
  end

  @doc false
  # Link quality: the share of frames that arrived (sequence gaps are
  # losses), then what Dolphin.Vehicles.LinkQuality measured, if it has.
  @spec link(map() | nil) :: String.t()
  def link(nil), do: "-"
  def link(%{received: 0}), do: "-"

  def link(%{received: r, lost: l} = link) do
    pct = floor(r * 100 / (r + l))
    frames = if l == 0, do: "100 %", else: "#{pct} % (#{l} lost)"
    Enum.join([frames | link_figures(link)], ", ")
  end

  @doc false
  # The measured round trip and loss each way, as far as known: ["45 ms", "loss in 10 % / out 12 %"].
  @spec link_figures(map()) :: [String.t()]
  def link_figures(link) do
    rtt = if is_number(link[:rtt_ms]), do: ["#{round(link[:rtt_ms])} ms"], else: []

    loss =
      case {link[:loss_in], link[:loss_out]} do
        {i, o} when is_number(i) and is_number(o) -> ["loss in #{round(i * 100)} % / out #{round(o * 100)} %"]
        _ -> []
      end

    rtt ++ loss
  end

  @doc false
  @spec seen(number() | nil, boolean()) :: String.t()
  def seen(nil, _lost?), do: "never"
  def seen(ms, true), do: "LOST " <> duration(ms)
  def seen(ms, false), do: duration(max(ms, 0)) <> " ago"

  @doc false
  # A MAV_TYPE name as words: :mav_type_quadrotor -> "quadrotor".
  @spec type_name(non_neg_integer() | nil) :: String.t() | nil
  def type_name(nil), do: nil

  def type_name(n), do: Dolphin.Vehicles.View.mav_type_name(n)

  @doc false
  # A task in one line: `17 mission "Survey Area"`.
  @spec task_label(map()) :: String.t()
  def task_label(%{task_id: id, kind: kind, name: name}), do: "#{id} #{kind} #{inspect(cut(name, 40))}"

  defp cut(nil, _n), do: ""
  defp cut(text, n), do: if(String.length(text) > n, do: String.slice(text, 0, n - 1) <> "…", else: text)

  # --- tasks -----------------------------------------------------------------------

  @doc false
  # The tasks() tree. `groups`: the scripts and task runs of the console and
  # the others found running, each %{text, state, runs: [run_id]}, plus
  # `runs` (%{run, text}), `tasks` (Dolphin.Engine.tasks/0 entries) and
  # task `states` (task_id => text). Runs of no group come last, alone.
  @spec task_tree([map()], [map()], [map()], %{integer() => String.t()}) :: String.t()
  def task_tree([], [], _tasks, _states), do: "no tasks running"

  def task_tree(groups, runs, tasks, states) do
    children = Enum.group_by(tasks, & &1.parent_id)
    roots = Enum.group_by(Map.get(children, nil, []), & &1.run)
    grouped = groups |> Enum.flat_map(& &1.runs) |> MapSet.new()

    run_node = fn run ->
      %{text: run.text, state: nil, children: Enum.map(Map.get(roots, run.run, []), &task_node(&1, children, states))}
    end

    by_id = Map.new(runs, &{&1.run, &1})

    group_nodes =
      Enum.map(groups, fn g ->
        %{text: g.text, state: g.state, children: for(id <- g.runs, run = by_id[id], do: run_node.(run))}
      end)

    loose = for run <- runs, not MapSet.member?(grouped, run.run), do: run_node.(run)
    tree(group_nodes ++ loose)
  end

  defp task_node(task, children, states) do
    vehicle = if task.vehicle, do: "  vehicle #{task.vehicle}", else: ""

    %{
      text: task_label(task) <> vehicle,
      state: Map.get(states, task.task_id, "running"),
      children: children |> Map.get(task.task_id, []) |> Enum.sort_by(& &1.task_id) |> Enum.map(&task_node(&1, children, states))
    }
  end

  @doc false
  # What a task is doing, from the events about it (the console's event
  # store keeps these per running task).
  @spec task_state(String.t() | nil, map()) :: String.t()
  def task_state(_old, %{event: :task_started, kind: kind}) when kind in [:wait_for, :condition], do: "waiting"
  def task_state(_old, %{event: :task_started, vehicle: v}) when v != nil, do: "starting"
  def task_state(_old, %{event: :task_started}), do: "running"
  def task_state(_old, %{event: :condition_met, branch: b}) when is_integer(b), do: "branch #{b} chosen"
  def task_state(_old, %{event: :condition_met}), do: "condition met"

  def task_state(_old, %{event: :task_progress, progress: %{current: c, total: t} = p}) when is_integer(t) and t > 0,
    do: "item #{c || 0}/#{t}" <> if(is_integer(p[:reached]) and p[:reached] > 0, do: ", reached #{p.reached}", else: "")

  def task_state(_old, %{event: :task_progress, progress: p}) when is_map(p),
    do: p |> Enum.sort() |> Enum.map_join(", ", fn {k, v} -> "#{k} #{inspect(v, charlists: :as_lists)}" end)

  def task_state(old, _event), do: old || "running"

  # --- one vehicle -------------------------------------------------------------------

  @doc false
  # STATUSTEXTs (newest first, as the vehicle state keeps them) oldest first,
  # with their MAV_SEVERITY.
  @spec messages([{integer(), String.t()}]) :: String.t()
  def messages([]), do: "no messages"
  def messages(texts), do: texts |> Enum.reverse() |> Enum.map_join("\n", fn {sev, text} -> String.pad_trailing(severity(sev), 9) <> " " <> text end)

  @doc false
  # The STATUSTEXTs of `now` that `before` did not have (both newest first,
  # as a vehicle state keeps its last 20): the longest prefix of `now` whose
  # rest is what `before` began with.
  @spec new_texts(list(), list()) :: list()
  def new_texts(before, now), do: Dolphin.Vehicles.State.texts_since(before, now)

  @doc false
  @spec severity(integer()) :: String.t()
  def severity(n), do: Enum.at(~w(EMERGENCY ALERT CRITICAL ERROR WARNING NOTICE INFO DEBUG), n, "#{n}")

  @doc false
  # One line of the watch ticker, from a vehicle state (Dolphin.Vehicles.State)
  # and whether the vehicle is lost (its view says so: the state does not);
  # `t_ms` is the real time since the watch began.
  @spec ticker(map(), boolean(), integer()) :: String.t()
  def ticker(state, lost?, t_ms) do
    pos = state.position || %{}
    mission = state.mission || %{}

    [
      String.pad_leading(seconds(t_ms), 7),
      String.pad_trailing(mode(state.mode), 9),
      if(state.armed, do: "ARMED   ", else: "disarmed"),
      bar(state.battery) <> " " <> String.pad_leading(battery(state.battery), 5),
      position(pos[:lat], pos[:lon]),
      "alt " <> String.pad_leading(metres(pos[:relative_alt]), 8),
      "hdg " <> if(pos[:heading], do: String.pad_leading("#{round(pos[:heading])}", 3), else: "  -"),
      "mission " <> mission_progress(mission),
      to_string(state.landed || ""),
      if(lost?, do: "LOST", else: "")
    ]
    |> Enum.join("  ")
    |> String.trim_trailing()
  end

  defp mission_progress(%{current: c, total: t}) when is_integer(t) and t > 0, do: "#{c || 0}/#{t}"
  defp mission_progress(_), do: "-"

  @doc false
  # Mission items (MISSION_ITEM_INT structs) as the table Dolphin.Mission's
  # inspect prints: seq, command, where, params.
  @spec items([struct()]) :: String.t()
  def items([]), do: "no mission items"

  def items(items) do
    Enum.map_join(items, "\n", fn item ->
      name = Dolphin.Mission.item_name(item)

      where =
        cond do
          item.frame == 2 -> ""
          item.frame in [0, 5] -> "#{e7(item.x)}, #{e7(item.y)}, #{num(item.z)} m AMSL  "
          item.frame in [3, 6] -> "#{e7(item.x)}, #{e7(item.y)}, #{num(item.z)} m above home  "
          true -> "x #{item.x}, y #{item.y}, z #{num(item.z)}, frame #{item.frame}  "
        end

      params = Enum.map_join([item.param1, item.param2, item.param3, item.param4], ", ", &num/1)
      String.pad_leading(Integer.to_string(item.seq), 4) <> " " <> String.pad_trailing(name, 20) <> " " <> where <> "[" <> params <> "]"
    end)
  end

  defp e7(n), do: :erlang.float_to_binary(n / 1.0e7, decimals: 7)

  @doc false
  @spec num(term()) :: String.t()
  def num(:nan), do: "NaN"
  def num(f) when is_float(f) and f == trunc(f) and abs(f) < 1.0e15, do: Integer.to_string(trunc(f))
  def num(f) when is_float(f), do: Location.format(f, 6)
  def num(other), do: to_string(other)
end
