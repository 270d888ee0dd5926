defmodule Mix.Tasks.Dolphin.Sim do
  @shortdoc "Runs simulated ArduCopters for any ground station to fly"

  @moduledoc """
  Runs the built-in simulator alone, so that any ground station
  (QGroundControl, MAVProxy, a pymavlink script, or another Dolphin) can fly it.

      mix dolphin.sim --count 3 --gcs udpout:127.0.0.1:14550 --speedup 5

  Each vehicle sends from its own UDP port to the ground station's endpoint, as
  ArduPilot SITL's `--serial0 udpclient:HOST:PORT` does; system ids are 1..N.

  ## Options

    * `--count N` — how many vehicles (default 1)
    * `--gcs udpout:HOST:PORT` — where the ground station listens (default
      `udpout:127.0.0.1:14550`, QGroundControl's port)
    * `--speedup K` — run K times faster than real time (default 1)
    * `--home LAT,LON,ALT` — where the fleet stands (default the report's
      40.444233,-7.375234,820); vehicles are spread 30 m apart
    * `--first-sysid N` — the first system id (default 1)
    * `--camera` — every vehicle carries a camera (component 100)
    * `--ekf-ready SECONDS` — vehicle seconds from boot until arming is possible (default 15)
    * `--battery-failsafe rtl|land|none` — what a low battery does (default none, as ArduPilot)
    * `--seed N` — seeds the faults' randomness
    * `--for SECONDS` — stop after that many seconds of vehicle time (default: until interrupted)
    * `--quiet` — no status lines

  While it runs, a status line per vehicle is printed every 10 seconds (real time).
  """

  use Mix.Task

  @switches [
    count: :integer,
    gcs: :string,
    speedup: :float,
    home: :string,
    first_sysid: :integer,
    camera: :boolean,
    ekf_ready: :float,
    battery_failsafe: :string,
    seed: :integer,
    for: :float,
    quiet: :boolean
  ]

  @impl Mix.Task
  def run(argv) do
    # A closed pipe (`| head`) ends the task at once, quietly.
    Dolphin.CLI.Stdout.watch()

    opts = parse!(argv)
    Mix.Task.run("app.start")
    sysids = start!(opts)
    unless opts[:quiet], do: Mix.shell().info("simulating #{length(sysids)} vehicle(s) #{Dolphin.Fleet.VehicleSet.format(sysids)}, sending to #{opts[:gcs]}")
    wait(sysids, opts)
  end

  @doc false
  # The options, checked, as `Dolphin.Sim.start/1` takes them (plus :for and :quiet).
  @spec parse!([String.t()]) :: keyword()
  def parse!(argv) do
    case OptionParser.parse(argv, strict: @switches) do
      {opts, [], []} ->
        opts
        |> Keyword.put_new(:gcs, "udpout:127.0.0.1:14550")
        |> Keyword.update(:home, nil, &home!/1)
        |> Keyword.update(:ekf_ready, nil, &round(&1 * 1000))
        |> Keyword.update(:battery_failsafe, nil, &failsafe!/1)
        |> rename(:ekf_ready, :ekf_ready_ms)
        |> Enum.reject(fn {_k, v} -> v == nil end)

      {_, [extra | _], _} ->
        Mix.raise("mix dolphin.sim: unexpected argument #{inspect(extra)} (see mix help dolphin.sim)")

      {_, _, [{switch, value} | _]} ->
        Mix.raise("mix dolphin.sim: bad option #{switch}#{if value, do: " " <> value, else: ""} (see mix help dolphin.sim)")
    end
  end

  @doc false
  def start!(opts) do
    camera = if opts[:camera], do: [camera: true], else: []

    case Dolphin.Sim.start(Keyword.drop(opts, [:for, :quiet, :camera]) ++ camera) do
      {:ok, sysids} -> sysids
      {:error, e} -> Mix.raise("mix dolphin.sim: #{Exception.message(e)}")
    end
  end

  defp wait(sysids, opts) do
    until = if opts[:for], do: Dolphin.Clock.now_ms() + round(opts[:for] * 1000), else: :infinity
    loop(sysids, until, opts[:quiet])
  end

  defp loop(sysids, until, quiet?) do
    left = if until == :infinity, do: 10_000, else: min(10_000, Dolphin.Clock.to_real_ms(until - Dolphin.Clock.now_ms()))

    if left <= 0 do
      Dolphin.Sim.stop()
    else
      Process.sleep(left)
      unless quiet?, do: Enum.each(sysids, &status/1)
      loop(sysids, until, quiet?)
    end
  end

  defp status(sysid) do
    case Dolphin.Sim.info(sysid) do
      {:ok, i} ->
        p = i.position

        Mix.shell().info(
          "vehicle #{sysid}: #{i.mode}#{if i.armed, do: " armed", else: ""} #{i.landed} " <>
            "#{Float.round(p.lat, 6)},#{Float.round(p.lon, 6)} #{Float.round(p.relative_alt, 1)} m " <>
            "battery #{round(i.battery * 100)} % mission #{i.current}/#{length(i.mission)} photos #{i.photos}"
        )

      {:error, :unknown_vehicle} ->
        Mix.shell().info("vehicle #{sysid}: gone")
    end
  end

  defp home!(string) do
    with [lat, lon, alt] <- String.split(string, ","),
         {lat, ""} <- Float.parse(lat),
         {lon, ""} <- Float.parse(lon),
         {alt, ""} <- Float.parse(alt) do
      %{lat: lat, lon: lon, alt: alt}
    else
      _ -> Mix.raise("mix dolphin.sim: bad --home #{inspect(string)}: LAT,LON,ALT in degrees and metres, e.g. 40.444233,-7.375234,820")
    end
  end

  defp failsafe!("rtl"), do: :rtl
  defp failsafe!("land"), do: :land
  defp failsafe!("none"), do: :none
  defp failsafe!(other), do: Mix.raise("mix dolphin.sim: bad --battery-failsafe #{inspect(other)}: rtl, land or none")

  defp rename(opts, from, to) do
    case Keyword.pop(opts, from) do
      {nil, opts} -> opts
      {value, opts} -> Keyword.put(opts, to, value)
    end
  end
end
