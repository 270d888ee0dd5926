defmodule Dolphin.Web.LiveTest do
  use ExUnit.Case, async: true

  alias Dolphin.Vehicles.View
  alias Dolphin.Web.Live

  defp view(id, lat, opts \\ []) do
    struct(%View{id: id, type: :uav, battery: 0.9, position: Dolphin.Geo.location(lat, -7.375, 820), relative_altitude: 15.0, mode: :guided, armed?: true}, opts)
  end

  # The vehicle flies north one position per clock second.
  defp fly(live, id, n, from \\ 0) do
    Enum.reduce(from..(from + n - 1), live, fn i, live -> Live.view(live, view(id, 40.44 + i / 100_000), i * 1000) end)
  end

  test "keeps a bounded track: past its bound, every other position, the first and the last kept" do
    live = fly(Live.new(0), 1, 10_000)
    positions = live.vehicles[1].positions
    assert length(positions) <= 4_000
    assert live.counts[1] == length(positions)
    # Newest first (times in clock microseconds, as a log's): the last position seen and the very first are both there.
    assert {9_999_000_000, lat_last, _, _, _, _} = hd(positions)
    assert lat_last == round((40.44 + 9_999 / 100_000) * 1.0e7)
    assert {0, _, _, _, _, _} = List.last(positions)
  end

  test "a view that does not move adds no position; battery, mode and arming only when they change" do
    live = Live.new(0) |> Live.view(view(1, 40.44), 1000) |> Live.view(view(1, 40.44), 2000) |> Live.view(view(1, 40.44, battery: 0.5, mode: :rtl), 3000)
    v = live.vehicles[1]
    assert length(v.positions) == 1
    assert [{3_000_000, 50}, {1_000_000, 90}] = v.battery
    assert [{3_000_000, :rtl}, {1_000_000, :guided}] = v.modes
    assert [{1_000_000, true}] = v.arming
  end

  test "a declared sensor's readings: plotted as they come, and each vehicle's latest in its row" do
    smoke = {:named_value, "SMOKE"}
    reading = fn value, at, stale -> %{smoke => %{value: value, at: at, compid: 191, position: nil, history: [], stale: stale}} end

    live =
      Live.new(0)
      |> Live.event(%{event: :sensor_declared, at_ms: 0, sensor: :smoke, source: "NAMED_VALUE SMOKE", unit: nil, scale: 1.0, offset: 0.0, stale_after: 5_000})
      |> Live.view(view(1, 40.44, sensors: reading.(0.2, 1_000, [])), 1_000)
      |> Live.view(view(1, 40.44, sensors: reading.(0.2, 1_000, [])), 1_500)
      |> Live.view(view(1, 40.44, sensors: reading.(0.61, 2_000, [])), 2_000)
      |> Live.view(view(2, 40.45, sensors: reading.(0.1, 2_000, [5_000])), 7_000)

    # One sample per reading, not per view.
    assert [{2_000_000, 0.61}, {1_000_000, 0.2}] = live.vehicles[1].sensors[smoke]
    page = Live.page(live, 10_000)
    assert page =~ ~s(<svg class="plot sensor")
    assert page =~ ~s(<td class="sensors">smoke 0.61</td>)
    assert page =~ ~s[<td class="sensors">smoke 0.10 (stale)</td>]
  end

  test "keeps the last events, and the task each vehicle flies now" do
    live = Enum.reduce(1..5_100, Live.new(0), fn i, live -> Live.event(live, %{event: :message, at_ms: i, text: "m#{i}", run: 1}) end)
    assert live.n_events == 5_000
    assert %{"text" => "m101"} = :queue.head(live.events)

    live = Live.event(live, %{event: :task_started, at_ms: 6000, run: 1, task_id: 7, parent_id: nil, kind: :mission, name: "North", vehicle: 1})
    assert live.running == %{1 => {7, "mission", "North"}}
    live = Live.event(live, %{event: :task_finished, at_ms: 7000, run: 1, task_id: 7, result: :done})
    assert live.running == %{}
  end

  test "the page is the report's, with the vehicles now and a dot where each one is; its pieces are its changing parts" do
    live =
      Live.new(0, title: "Live <test>", tlog: "logs/run.tlog", started_at: ~U[2026-01-02 03:04:05Z])
      |> fly(1, 20)
      |> fly(2, 10)
      |> Live.event(%{event: :task_started, at_ms: 5000, run: 1, task_id: 3, parent_id: nil, kind: :mission, name: "North", vehicle: 1})

    page = Live.page(live, 30_000)
    assert page =~ "<h1>Live &lt;test&gt;</h1>"
    assert page =~ "started 2026-01-02 03:04:05Z"
    assert page =~ "the telemetry log is written to <code"
    assert page =~ ~s(<tr class="v-1 live-vehicle" data-vehicle="1" data-lat="40.4401900")
    assert page =~ "3 mission “North”"
    assert page =~ ~s(<circle class="now v-1" data-vehicle="1")
    assert page =~ ~s(<circle class="now v-2" data-vehicle="2")
    assert page =~ ~s(data-name="North" data-kind="mission" data-result="unfinished")

    # A fleet of one page: counted, no pages.
    assert page =~ ~s(<p class="fleet-counts">2 vehicles: 2 connected, none lost; 2 armed; 1 flying a task; emptiest batteries: 1 90 %, 2 90 %</p>)
    refute page =~ ~s(class="pager")

    pieces = Live.pieces(page)
    assert Enum.map(pieces, &elem(&1, 0)) == ~w(when legend live-status summary map-section timeline-section plots)
    # Each piece is what its element holds: put back in place, it is the page again.
    for {id, html} <- pieces, id not in ["when", "legend"], do: assert(page =~ ~s(<section id="#{id}">) <> html <> "</section>")
  end

  test "the fence a vehicle was given is drawn on the map; two vehicles too close, and the hold, on the plot and the time line" do
    base = Dolphin.Geo.location(40.44, -7.375, 820)
    {:ok, zone} = Dolphin.Geo.Shapes.polygon(for {n, e} <- [{50, -30}, {50, 30}, {80, 30}, {80, -30}], do: Dolphin.Geo.offset(base, n, e))
    items = Dolphin.Fence.to_items(%Dolphin.Fence{exclude: [zone], rally: [Dolphin.Geo.offset(base, 0, 60, 30)]}, base)

    fence = %{
      event: :fence_applied,
      at_ms: 1000,
      vehicle: 1,
      name: "North",
      fence: for(i <- items.fence, do: [i.command, i.x, i.y, i.param1]),
      rally: for(i <- items.rally, do: [i.x, i.y, i.z])
    }

    hold = %{event: :separation_hold, at_ms: 4000, vehicle: 2, other: 1, action: :hold, distance: 12.0, height: 0.0, closest: 2.0, in_s: 3.0, limit_m: 20.0, limit_height_m: 10.0}

    # Vehicle 2 flies beside vehicle 1, 11 m east of it.
    live =
      Live.new(0)
      |> Live.event(fence)
      |> fly(1, 10)
      |> then(fn live ->
        Enum.reduce(0..9, live, fn i, live -> Live.view(live, view(2, 40.44 + i / 100_000, position: Dolphin.Geo.offset(Dolphin.Geo.location(40.44 + i / 100_000, -7.375, 820), 0, 11)), i * 1000) end)
      end)
      |> Live.event(hold)

    page = Live.page(live, 10_000)
    assert [_] = Regex.scan(~r/<polygon class="zone exclusion" points="[^"]+"/, page)
    assert page =~ ~s(<text class="rally")
    assert page =~ ~s(<svg class="plot separation")
    assert page =~ ~r/least 11\.0 m at [^,]+, vehicles [12] and [12]/
    assert page =~ ~s(<g class="mark mark-separation_hold">)
  end

  test "a fleet of more than a page: every vehicle counted, one page drawn (in name order), links to the pages beside it" do
    ids = Enum.to_list(1..100) ++ for(n <- 1..20, do: "#{n}@sim2")

    live =
      Enum.reduce(ids, Live.new(0), fn id, live ->
        opts = %{7 => [connected?: false], 33 => [battery: 0.12], "4@sim2" => [battery: 0.2]}
        Enum.reduce(0..1, live, fn i, live -> Live.view(live, view(id, 40.44 + i / 100_000, Map.get(opts, id, [])), i * 1000) end)
      end)
      |> Live.event(%{event: :task_started, at_ms: 1500, run: 1, task_id: 1, parent_id: nil, kind: :mission, name: "North", vehicle: 1})
      |> Live.event(%{event: :task_started, at_ms: 1500, run: 1, task_id: 2, parent_id: nil, kind: :mission, name: "South", vehicle: 60})
      |> Live.event(%{event: :message, at_ms: 1600, run: 1, text: "to every page"})

    assert Live.pages(live) == 3
    counts = ~s[<p class="fleet-counts">120 vehicles: 119 connected, <b>1 lost</b> (7); 120 armed; 2 flying a task; emptiest batteries: 33 12 %, 4@sim2 20 %, 1 90 %, 2 90 %, 3 90 %</p>]

    second = Live.page(live, 2_000, 2)
    assert second =~ counts

    assert second =~
             ~s[<nav class="pager"><a href="?page=1">‹ page 1</a> · vehicles 51–100 of 120 (51 to 100), page 2 of 3, on the map and in every section below · <a href="?page=3">page 3 ›</a></nav>]

    rows = Regex.scan(~r/<tr class="v-(\S+) live-vehicle"/, second, capture: :all_but_first)
    assert rows == for(id <- 51..100, do: ["#{id}"])
    # The report's sections draw the page's vehicles, and the events that concern them or none.
    assert second =~ ~s(<circle class="now v-60")
    refute second =~ ~s(<circle class="now v-1")
    assert second =~ ~s(data-name="South")
    refute second =~ ~s(data-name="North")

    # Past the last page: the last, qualified names by network and system id.
    last = Live.page(live, 2_000, 99)
    assert last =~ counts
    assert last =~ ~s[vehicles 101–120 of 120 (1@sim2 to 20@sim2), page 3 of 3]
    refute last =~ "?page=4"
    assert Regex.scan(~r/<tr class="v-(\S+) live-vehicle"/, last, capture: :all_but_first) == for(n <- 1..20, do: ["#{n}@sim2"])
    assert Live.page(live, 2_000) =~ ~s(data-name="North")
  end

  test "a page with no vehicle yet" do
    page = Live.page(Live.new(0), 0)
    assert page =~ ~s(<section id="live-status">)
    assert length(Live.pieces(page)) == 7
  end
end
