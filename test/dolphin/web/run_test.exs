defmodule Dolphin.Web.RunTest do
  # Its own Dolphin.Instance (its vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.Test.Wait
  alias Mix.Tasks.Dolphin.Run

  @moduletag :tmp_dir
  @moduletag timeout: 180_000

  setup do
    {:ok, _} = Application.ensure_all_started(:inets)
    Dolphin.Test.GroundStation.forget_vehicles()
    Dolphin.Test.Instance.on_exit(&Dolphin.Test.GroundStation.forget_vehicles/0)
  end

  # One vehicle flies 400 m north and back: long enough to be seen moving.
  @script """
  use Dolphin.Script

  base = location(40.444233, -7.375234, 820)

  north =
    mission "North" do
      home base
      take_off location(40.444233, -7.375234, 840)
      move 400, 0, 0
      return_home_and_land()
    end

  v = pick(type: :uav, timeout: seconds(30))
  execute on(north, v)
  release(v)
  """

  defp script(dir, source \\ @script) do
    path = Path.join(dir, "flight.exs")
    File.write!(path, source)
    path
  end

  defp main(argv) do
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    code = Run.main(argv, out: out, err: err)
    {code, elem(StringIO.contents(out), 1), elem(StringIO.contents(err), 1)}
  end

  defp get(url) do
    {:ok, {{_, 200, _}, _, body}} = :httpc.request(:get, {String.to_charlist(url), []}, [timeout: 10_000], body_format: :binary)
    body
  end

  # The vehicles' rows of the page's "Now" table: id => {lat, lon} (nil before a position).
  defp positions(page) do
    for [id, lat, lon] <- Regex.scan(~r/<tr class="v-\d+ live-vehicle" data-vehicle="(\d+)" data-lat="([^"]*)" data-lon="([^"]*)"/, page, capture: :all_but_first), into: %{} do
      {String.to_integer(id), if(lat != "", do: {String.to_float(lat), String.to_float(lon)})}
    end
  end

  describe "usage" do
    test "--web takes a port, --web-bind an address and goes with --web, --report needs a telemetry log", %{tmp_dir: dir} do
      ok = script(dir, "use Dolphin.Script\n")
      assert {2, _, err} = main([ok, "--fake", "1", "--web", "70000"])
      assert err =~ "--web 70000: a TCP port from 1 to 65535 (0: any free one)"
      assert {2, _, err} = main([ok, "--fake", "1", "--web", "port"])
      assert err =~ "--web port: a TCP port from 1 to 65535"
      assert {2, _, err} = main([ok, "--fake", "1", "--web-bind", "127.0.0.1"])
      assert err =~ "--web-bind goes with --web PORT"
      assert {2, _, err} = main([ok, "--fake", "1", "--web", "0", "--web-bind", "localhost"])
      assert err =~ ~s(--web-bind takes an IP address, got "localhost")
      assert {2, _, err} = main([ok, "--sim", "1", "--no-tlog", "--report", Path.join(dir, "r.html")])
      assert err =~ "not with --no-tlog"
      assert {2, _, err} = main([ok, "--fake", "1", "--report", Path.join(dir, "r.html")])
      assert err =~ "not with --fake"
    end

    test "a --web port in use: exit status 1, nothing run", %{tmp_dir: dir} do
      Dolphin.Events.subscribe()
      {:ok, busy} = :gen_tcp.listen(0, ip: {127, 0, 0, 1})
      {:ok, port} = :inet.port(busy)
      ok = script(dir, "use Dolphin.Script\nmessage(\"hi\")\n")
      assert {1, _, err} = main([ok, "--fake", "1", "--web", "#{port}"])
      assert err =~ "mix dolphin.run: --web #{port}: cannot serve the live view on 127.0.0.1:#{port}: the port is in use"
      refute_received {:dolphin, :events, %{event: :message}}
      :gen_tcp.close(busy)
    end
  end

  test "--web serves the run live, --report writes its flight report at the end", %{tmp_dir: dir} do
    flight = script(dir)
    report = Path.join(dir, "report.html")
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    argv = [flight, "--sim", "1", "--speedup", "10", "--tlog", Path.join(dir, "flight.tlog"), "--events", Path.join(dir, "flight.jsonl"), "--web", "0", "--report", report]
    run = Task.async(fn -> Run.main(argv, out: out, err: err) end)

    # (The run checks the script first, in a dry run other tests may hold a while on a busy machine.)
    url =
      Wait.until(
        fn -> with [_, url] <- Regex.run(~r{live view: (http://127\.0\.0\.1:\d+/)}, elem(StringIO.contents(out), 1)), do: url end,
        6_000,
        fn -> inspect({StringIO.contents(out), StringIO.contents(err)}) end
      )

    # Once the vehicle flies its mission: where it is, and its task on the time line.
    first =
      Wait.until(fn ->
        page = get(url)
        match?(%{1 => {_, _}}, positions(page)) and page =~ ~s(data-kind="mission") and page
      end)

    assert first =~ ~s(<g class="task" data-vehicle="1" data-name="North" data-kind="mission" data-result="unfinished">)
    {lat0, lon0} = positions(first)[1]

    # Later, the same page shows it elsewhere, its track longer.
    later =
      Wait.until(fn ->
        page = get(url)
        {lat, _} = positions(page)[1]
        abs(lat - lat0) > 0.0002 and page
      end)

    assert {_lat, lon} = positions(later)[1]
    assert_in_delta lon, lon0, 0.0002, "it flies north"
    [points0] = Regex.run(~r/class="flown" data-vehicle="1" data-points="(\d+)"/, first, capture: :all_but_first)
    [points1] = Regex.run(~r/class="flown" data-vehicle="1" data-points="(\d+)"/, later, capture: :all_but_first)
    assert String.to_integer(points1) >= String.to_integer(points0)

    assert Task.await(run, 170_000) == 0, "the run failed: #{elem(StringIO.contents(err), 1)}"
    {_, said} = StringIO.contents(out)
    assert said =~ "flight report: #{Path.expand(report)} (1 vehicle(s), "
    assert File.read!(report) =~ ~s(data-name="North" data-kind="mission" data-result="done")

    # The run is over: so is its live view.
    assert {:error, _} = :httpc.request(:get, {String.to_charlist(url), []}, [timeout: 5_000], [])
  end
end
