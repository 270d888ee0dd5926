# What drawing the live view costs for a large fleet: a live view's model
# (Dolphin.Web.Live) fed the views of BENCH_VEHICLES vehicles (default 1,000)
# that each flew BENCH_POSITIONS positions (default 120, two minutes at 1 Hz)
# and started a mission (a task_started event each), then its first page
# drawn BENCH_ROUNDS times (default 5), as the view does for its clients at
# each frame (at most four a second). Prints the time to feed the model, the
# time per page (min / median / max) and the page's size.
#
#   MIX_ENV=prod mix run bench/live_view.exs
#
# The view waits four times a page's drawing time between frames: a page that
# takes 1 s to draw is sent every 4 s.
defmodule LiveViewBench do
  alias Dolphin.Vehicles.View
  alias Dolphin.Web.Live

  def main do
    n = env("BENCH_VEHICLES", 1_000)
    positions = env("BENCH_POSITIONS", 120)
    rounds = env("BENCH_ROUNDS", 5)
    ids = Enum.to_list(1..min(n, 254)) ++ for(i <- 255..n//1, do: "#{rem(i - 255, 254) + 1}@sim#{div(i - 255, 254) + 2}")

    {feed_us, live} =
      :timer.tc(fn ->
        live =
          Enum.reduce(1..positions, Live.new(0), fn t, live ->
            Enum.reduce(ids, live, fn id, live -> Live.view(live, view(id, t), t * 1_000) end)
          end)

        ids
        |> Enum.with_index(1)
        |> Enum.reduce(live, fn {id, i}, live -> Live.event(live, %{event: :task_started, at_ms: 500, run: 1, task_id: i, parent_id: nil, kind: :mission, name: "Strip #{i}", vehicle: id}) end)
      end)

    now = (positions + 1) * 1_000

    times =
      for _ <- 1..rounds do
        {us, page} = :timer.tc(fn -> Live.page(live, now) end)
        {us, byte_size(page)}
      end

    sorted = times |> Enum.map(&elem(&1, 0)) |> Enum.sort()
    {_, size} = hd(times)

    IO.puts("""
    live view of #{n} vehicles, #{positions} positions each (#{n * positions} views fed in #{ms(feed_us)}: #{Float.round(feed_us / (n * positions), 2)} µs a view)
    its first page, #{rounds} times: #{ms(hd(sorted))} / #{ms(Enum.at(sorted, div(rounds, 2)))} / #{ms(List.last(sorted))} (min / median / max), #{Float.round(size / 1_000_000, 2)} MB
    rows in its "Now" table: #{length(Regex.scan(~r/ live-vehicle"/, Live.page(live, now)))}
    """)
  end

  # Vehicle `id` at second t: a strip of its own, flown north at 5 m/s.
  defp view(id, t) do
    k = :erlang.phash2(id, 10_000)
    lat = 40.44 + k * 0.0003 / 100 + t * 5 / 111_000
    lon = -7.375 + rem(k, 100) * 0.0006
    %View{id: id, type: :uav, battery: 1.0 - t / 1_000, position: Dolphin.Geo.location(lat, lon, 850), relative_altitude: 30.0, mode: :auto, armed?: true, connected?: true}
  end

  defp ms(us), do: "#{Float.round(us / 1000, 1)} ms"

  defp env(name, default) do
    case System.get_env(name) do
      nil -> default
      text -> String.to_integer(text)
    end
  end
end

LiveViewBench.main()
