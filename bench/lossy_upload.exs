# Mission upload to a real ArduCopter (SITL) over a bad radio link.
#
# Starts one ArduCopter SITL (Dolphin.SITL: ../shared/sitl/arducopter, or
# ARDUPILOT_SITL) at --speedup 1, behind an impairment proxy written in Elixir
# (test/support/udp_proxy.ex) that drops, duplicates and reorders datagrams
# each way. For every row (loss each way; 5 % duplicates and 5 % reordering
# on the lossy rows) and mission size, it uploads the mission RUNS times with
# each uploader:
#
#   ahead    the ground station's uploader: items sent ahead in a window,
#            resent on a timeout from the measured round trip (go-back-N)
#   request  the same uploader with sending ahead switched off: an item goes
#            out when the vehicle asks for it (as MAVProxy and QGroundControl
#            upload), resent after a timeout
#
# and reads every upload back (MISSION_REQUEST_LIST ... through the same
# link) to check it is exactly the mission sent. A run succeeds when the
# upload says :ok (or :unconfirmed: every item went out, the final ACK was
# lost) and the read-back is exact. Times are wall-clock seconds of the
# upload alone.
#
#   mix run bench/lossy_upload.exs [--runs 5] [--sizes 100,400] [--losses 0,10,20,30] [--speedup 1] [--uploaders ahead,request]
#
# Prints a Markdown table: median and max time, successes, median
# retransmissions, per row and uploader.

Code.require_file("../test/support/udp_proxy.ex", __DIR__)

alias Dolphin.{Clock, Mission, SITL, Vehicles}
alias Dolphin.MAVLink.Ardupilotmega, as: M
alias Dolphin.Test.UDPProxy

{opts, _, _} = OptionParser.parse(System.argv(), strict: [runs: :integer, sizes: :string, losses: :string, speedup: :integer, uploaders: :string])
ints = fn text -> text |> String.split(",") |> Enum.map(&String.to_integer/1) end
runs = Keyword.get(opts, :runs, 5)
sizes = ints.(Keyword.get(opts, :sizes, "100,400"))
losses = ints.(Keyword.get(opts, :losses, "0,10,20,30"))
speedup = Keyword.get(opts, :speedup, 1)
uploaders = opts |> Keyword.get(:uploaders, "ahead,request") |> String.split(",") |> Enum.map(&{&1, &1 == "ahead"})

unless SITL.available?() do
  IO.puts("no ArduCopter SITL binary (../shared/sitl/arducopter or ARDUPILOT_SITL): nothing to measure")
  System.halt(0)
end

Clock.set_speedup(speedup)
bench = self()

send_to = fn gcs_port ->
  {:ok, proxy} = UDPProxy.start_link(gcs: gcs_port, seed: 11)
  send(bench, {:proxy, proxy})
  UDPProxy.port(proxy)
end

{:ok, fleet} = SITL.start(1, send_to: send_to, charge_per_s: 0)
[id] = fleet.sysids
proxy = receive do: ({:proxy, p} -> p)

# Home first (ArduCopter's item 0), then waypoints 10 m apart near it.
{:ok, %{position: %{lat: lat, lon: lon}}} = Vehicles.state(id)

mission = fn n ->
  home = %M.MissionItemInt{frame: 0, command: 16, x: round(lat * 1.0e7), y: round(lon * 1.0e7), z: 0.0}
  [home | for(i <- 1..(n - 1)//1, do: %M.MissionItemInt{frame: 3, command: 16, autocontinue: 1, x: round(lat * 1.0e7) + i * 900, y: round(lon * 1.0e7) + rem(i, 7) * 900, z: 20.0 + rem(i, 5)})]
end

one = fn items, ahead? ->
  started = System.monotonic_time(:millisecond)
  upload = Vehicles.upload_mission(id, items, send_ahead: ahead?, progress_to: self())
  seconds = (System.monotonic_time(:millisecond) - started) / 1000
  done = receive do: ({:mission_done, :upload, d} -> d), after: (0 -> %{retransmissions: 0, transactions: 0})
  receive do: ({:mission_done, :download, _} -> :ok), after: (0 -> :ok)

  uploaded? = upload == :ok or match?({:error, %Dolphin.MissionError{result: :unconfirmed}}, upload)

  verdict =
    with true <- uploaded? || {:upload, upload},
         {:ok, back} <- Vehicles.download_mission(id),
         :ok <- Mission.compare_download(items, back) do
      :ok
    else
      {:upload, {:error, e}} -> {:failed, "upload: " <> Exception.message(e)}
      {:error, %Dolphin.MissionError{} = e} -> {:failed, "read-back: " <> Exception.message(e)}
      {:error, e} -> {:failed, "read-back differs: " <> Exception.message(e)}
    end

  # Flush what the transfers sent us.
  Stream.repeatedly(fn -> receive do: (m -> m), after: (0 -> nil) end) |> Enum.take_while(& &1)
  {seconds, verdict, done}
end

median = fn xs -> xs |> Enum.sort() |> Enum.at(div(length(xs) - 1, 2)) end

IO.puts("# mission upload to ArduCopter SITL (--speedup #{speedup}) through the impairment proxy, #{runs} runs per row")
IO.puts("# #{System.schedulers_online()} schedulers, OTP #{System.otp_release()}, #{Date.utc_today()}")
IO.puts("")
IO.puts("| loss each way | dup / reorder | items | uploader | median s | max s | exact | median retransmissions |")
IO.puts("| --- | --- | --- | --- | --- | --- | --- | --- |")

for loss <- losses, n <- sizes, {name, ahead?} <- uploaders do
  extra = if loss > 0, do: 0.05, else: 0.0
  :ok = UDPProxy.set(proxy, both: [loss: 0.0, duplicate: 0.0, reorder: 0.0])
  # The vehicle is left alone for a moment between rows (a failed upload may
  # still be open on it for its 8 s).
  Process.sleep(200)
  :ok = UDPProxy.set(proxy, both: [loss: loss / 100, duplicate: extra, reorder: extra])
  items = mission.(n)
  results = for _ <- 1..runs, do: one.(items, ahead?)

  times = Enum.map(results, &elem(&1, 0))
  ok = Enum.count(results, &(elem(&1, 1) == :ok))
  retrans = median.(Enum.map(results, &elem(&1, 2).retransmissions))
  failures = for {_, {:failed, why}, _} <- results, do: why

  IO.puts(
    "| #{loss} % | #{round(extra * 100)} % | #{n} | #{name} | #{Float.round(median.(times), 2)} | #{Float.round(Enum.max(times), 2)} | #{ok}/#{runs} | #{retrans} |" <>
      Enum.map_join(Enum.uniq(failures), "", &"\n<!-- failed: #{&1} -->")
  )
end

:ok = UDPProxy.set(proxy, both: [loss: 0.0, duplicate: 0.0, reorder: 0.0])
SITL.stop(fleet)
