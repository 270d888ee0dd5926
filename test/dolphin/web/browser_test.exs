defmodule Dolphin.Web.BrowserTest do
  # Its own Dolphin.Instance (its vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.Test.{Browser, Wait}

  @moduletag :browser
  @moduletag :tmp_dir
  @moduletag timeout: 240_000

  setup do
    {:ok, _} = Application.ensure_all_started(:inets)
    Dolphin.Test.GroundStation.forget_vehicles()
    Dolphin.Test.Instance.on_exit(&Dolphin.Test.GroundStation.forget_vehicles/0)
  end

  # Two vehicles: one flies 500 m north, the other 500 m east, then both
  # come back; what the page must show follows from this script.
  @script """
  use Dolphin.Script

  base = location(40.444233, -7.375234, 820)

  north =
    mission "North" do
      home base
      take_off location(40.444233, -7.375234, 840)
      move 500, 0, 0
      return_home_and_land()
    end

  east =
    mission "East" do
      home base
      take_off location(40.444233, -7.375234, 840)
      move 0, 500, 0
      return_home_and_land()
    end

  v1 = pick(type: :uav, timeout: seconds(30))
  v2 = pick(type: :uav, timeout: seconds(30))
  execute %{v1 => north, v2 => east}
  release(union(v1, v2))
  """

  defp get(url) do
    {:ok, {{_, 200, _}, _, body}} = :httpc.request(:get, {String.to_charlist(url), []}, [timeout: 10_000], body_format: :binary)
    body
  end

  # The attributes of each element `tag` whose class attribute begins with `class`.
  defp elements(dom, tag, class) do
    ~r/<#{tag} class="#{class}[^"]*"[^>]*>/
    |> Regex.scan(dom)
    |> Enum.map(fn [element] -> ~r/([\w-]+)="([^"]*)"/ |> Regex.scan(element) |> Map.new(fn [_, k, v] -> {k, v} end) end)
  end

  defp rows(dom), do: Map.new(elements(dom, "tr", "v-\\d+ live-vehicle"), fn row -> {row["data-vehicle"], row} end)

  # The page in the browser, once it has applied `frames` frames of the live stream.
  defp browse(url, profile, frames) do
    dom = Browser.dump_dom(url <> "?frames=#{frames}", profile, ["--virtual-time-budget=20000"])
    assert dom =~ ~s(data-frames="#{frames}"), "the page did not follow the stream"
    assert dom =~ ~s(id="live-state">snapshot<)
    dom
  end

  test "the live page shows the vehicles moving and their task bars growing", %{tmp_dir: dir} do
    flight = Path.join(dir, "flight.exs")
    File.write!(flight, @script)
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    argv = [flight, "--sim", "2", "--speedup", "5", "--tlog", Path.join(dir, "flight.tlog"), "--web", "0"]
    run = Task.async(fn -> Mix.Tasks.Dolphin.Run.main(argv, out: out, err: err) end)
    url = Wait.until(fn -> with [_, url] <- Regex.run(~r{live view: (http://127\.0\.0\.1:\d+/)}, elem(StringIO.contents(out), 1)), do: url end)

    # Both vehicles on their missions.
    Wait.until(fn -> length(Regex.scan(~r/data-kind="mission" data-result="unfinished"/, get(url))) == 2 end)
    profile = Path.join(dir, "chromium")
    first = browse(url, profile, 2)

    # A few seconds of flight later.
    lat = fn dom, id -> String.to_float(rows(dom)[id]["data-lat"]) end
    north = Regex.run(~r/data-vehicle="(\d+)" data-name="North"/, first, capture: :all_but_first) |> hd()
    Wait.until(fn -> abs(lat.(get(url), north) - lat.(first, north)) > 0.0005 end)
    later = browse(url, profile, 2)

    for {id, row} <- rows(first) do
      assert rows(later)[id]["data-lat"] != row["data-lat"] or rows(later)[id]["data-lon"] != row["data-lon"], "vehicle #{id} did not move"
    end

    # Its dot on the map moved as far north as the vehicle did (up: SVG's y
    # grows downwards; metres on the map). A loaded machine's browser may
    # take long enough for the vehicle to turn back between the two pages:
    # the dot follows it either way.
    [dot1] = for d <- elements(first, "circle", "now"), d["data-vehicle"] == north, do: d
    [dot2] = for d <- elements(later, "circle", "now"), d["data-vehicle"] == north, do: d
    moved_m = (lat.(later, north) - lat.(first, north)) * 111_195
    dot_moved_m = String.to_float(dot1["cy"]) - String.to_float(dot2["cy"])
    assert abs(moved_m) > 10
    assert_in_delta dot_moved_m, moved_m, 5 + 0.02 * abs(moved_m)

    # A bar per mission on its vehicle's lane, longer later.
    bars = fn dom -> for t <- elements(dom, "g", "task"), t["data-kind"] == "mission", into: %{}, do: {t["data-name"], t} end
    assert %{"North" => %{"data-result" => "unfinished"}, "East" => %{"data-result" => "unfinished"}} = bars.(first)

    width = fn dom, name ->
      [w] = Regex.run(~r/data-name="#{name}"[^>]*>\s*<rect class="task-bar[^"]*" x="[^"]*" y="[^"]*" width="([\d.]+)"/, dom, capture: :all_but_first)
      String.to_float(w)
    end

    assert width.(later, "North") > width.(first, "North")

    # And a person can look at it.
    png = Path.join(dir, "live.png")
    Browser.screenshot(url <> "?frames=2", png, profile, {1400, 1600}, ["--virtual-time-budget=20000"])
    assert <<0x89, "PNG", _::binary>> = File.read!(png)
    if System.get_env("DOLPHIN_KEEP_SCREENSHOT"), do: File.cp!(png, System.get_env("DOLPHIN_KEEP_SCREENSHOT"))

    assert Task.await(run, 200_000) == 0, "the run failed: #{elem(StringIO.contents(err), 1)}"
  end

  test "a large fleet's page N (?page=N) follows its own page's stream", %{tmp_dir: dir} do
    {:ok, web} = Dolphin.Web.start(port: 0)
    on_exit(fn -> Dolphin.Web.stop(web) end)

    Dolphin.Test.WebFleet.show(web, for(i <- 1..60, do: "#{i}@browser"), fn id, i ->
      %Dolphin.Vehicles.View{id: id, type: :uav, battery: 0.7, position: Dolphin.Geo.location(40.44 + i / 10_000, -7.375, 820), relative_altitude: 20.0, mode: :guided, armed?: true}
    end)

    Wait.until(fn -> get(Dolphin.Web.url(web) <> "?page=2") =~ ~s(data-vehicle="60@browser") end)
    # The stream's first frame replaces the rows the page was served with: page 2's again only
    # if the page asked its stream for page 2.
    dom = Browser.dump_dom(Dolphin.Web.url(web) <> "?page=2&frames=1", Path.join(dir, "chromium"), ["--virtual-time-budget=20000"])
    assert dom =~ ~s(data-frames="1"), "the page did not follow the stream"
    page2 = for row <- elements(dom, "tr", "v-\\S+ live-vehicle"), do: row["data-vehicle"]
    assert page2 == for(i <- 51..60, do: "#{i}@browser")
  end
end
