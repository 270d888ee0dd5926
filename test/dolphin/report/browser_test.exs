defmodule Dolphin.Report.BrowserTest do
  # Its own Dolphin.Instance (its vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.Test.Browser

  @moduletag :browser
  @moduletag :tmp_dir
  @moduletag timeout: 180_000

  # The run's vehicles stay known to this node's ground station: forgotten after.
  setup do
    Dolphin.Test.Instance.on_exit(&Dolphin.Test.GroundStation.forget_vehicles/0)
  end

  # Two vehicles: one flies "North" to its end, the other flies "East" until
  # `during` stops it. What a person looking at the report must see follows
  # from this script and from what the run recorded, not from the report's
  # generator.
  @script """
  use Dolphin.Script

  base = location(40.444233, -7.375234, 820)

  north =
    mission "North" do
      home base
      take_off location(40.444233, -7.375234, 840)
      move 120, 0, 0
      move 0, 60, 0
      return_home_and_land()
    end

  east =
    mission "East" do
      home base
      take_off location(40.444233, -7.375234, 840)
      move 0, 400, 0
      move 0, 400, 0
      return_home_and_land()
    end

  v1 = pick(type: :uav, timeout: seconds(30))
  v2 = pick(type: :uav, timeout: seconds(30))
  execute %{v1 => north, v2 => during(seconds(40), east)}
  message("both flown")
  release(union(v1, v2))
  """

  defp run_script(dir) do
    script = Path.join(dir, "flight.exs")
    File.write!(script, @script)
    tlog = Path.join(dir, "flight.tlog")
    events = Path.join(dir, "flight.jsonl")
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    args = [script, "--sim", "2", "--speedup", "20", "--tlog", tlog, "--events", events, "--quiet"]
    code = Mix.Tasks.Dolphin.Run.main(args, out: out, err: err)
    assert code == 0, "the run failed: #{elem(StringIO.contents(out), 1)}#{elem(StringIO.contents(err), 1)}"
    {tlog, events}
  end

  # The attributes of each element `tag` of class `class` in the DOM.
  defp elements(dom, tag, class) do
    ~r/<#{tag} class="#{class}"[^>]*>/
    |> Regex.scan(dom)
    |> Enum.map(fn [element] -> ~r/([\w-]+)="([^"]*)"/ |> Regex.scan(element) |> Map.new(fn [_, k, v] -> {k, v} end) end)
  end

  test "the report of a simulated run shows a track per vehicle and each task's result", %{tmp_dir: dir} do
    {tlog, events} = run_script(dir)
    page = Path.join(dir, "report.html")
    assert {:ok, _summary} = Dolphin.Report.write(tlog, events, page)

    # What the run did, from its own record of events.
    recorded = events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(&:jiffy.decode(&1, [:return_maps, null_term: nil]))
    started = for %{"event" => "task_started", "kind" => "mission"} = e <- recorded, into: %{}, do: {e["name"], e["vehicle"]}
    assert %{"North" => north_vehicle, "East" => east_vehicle} = started
    vehicles = Enum.sort([north_vehicle, east_vehicle])

    profile = Path.join(dir, "chromium")
    dom = Browser.dump_dom(page, profile)
    assert dom =~ ~s(data-ready="yes"), "the page's script did not run to its end"

    # One flown track per vehicle, drawn (a length on screen) inside the map.
    tracks = elements(dom, "polyline", "flown")
    assert tracks |> Enum.map(&String.to_integer(&1["data-vehicle"])) |> Enum.sort() == vehicles

    for track <- tracks do
      assert String.to_integer(track["data-drawn-length"]) > 0, "vehicle #{track["data-vehicle"]}'s track is not drawn"
      assert track["data-on-screen"] == "yes", "vehicle #{track["data-vehicle"]}'s track leaves the map"
    end

    # Its planned paths too: each mission uploaded is there.
    assert elements(dom, "polyline", "planned") |> Enum.map(&String.to_integer(&1["data-vehicle"])) |> Enum.sort() == vehicles

    # A bar per mission on its vehicle's lane, coloured by how it ended.
    bars = for t <- elements(dom, "g", "task"), t["data-kind"] == "mission", do: {t["data-name"], String.to_integer(t["data-vehicle"]), t["data-result"], t["data-drawn-width"]}
    assert [{"East", ^east_vehicle, "stopped", east_w}, {"North", ^north_vehicle, "done", north_w}] = Enum.sort(bars)
    assert String.to_integer(east_w) > 0 and String.to_integer(north_w) > 0

    assert dom =~ ~r/id="script-result">done</
    assert dom =~ "message: both flown"

    # And a person can look at it.
    png = Path.join(dir, "report.png")
    Browser.screenshot(page, png, profile)
    assert <<0x89, "PNG", _::binary>> = File.read!(png)
    assert File.stat!(png).size > 20_000
  end
end
