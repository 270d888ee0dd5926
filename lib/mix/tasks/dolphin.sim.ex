defmodule Mix.Tasks.Dolphin.Sim do
  @shortdoc "Runs simulated ArduCopters for any ground station to fly"

  @moduledoc """
  Runs the built-in simulator alone, so that any ground station
  (QGroundControl, MAVProxy, a pymavlink script, or another Dolphin) can fly it.

      mix dolphin.sim --count 3 --gcs udpout:127.0.0.1:14550 --speedup 5

  Each vehicle sends from its own UDP port to the ground station's endpoint, as
  ArduPilot SITL's `--serial0 udpclient:HOST:PORT` does; system ids are 1..N.

  ## Options

    * `--count N` — how many vehicles (default 1; with `--first-sysid`,
      their system ids must fit in 1..254)
    * `--gcs udpout:HOST:PORT` — where the ground station listens (default
      `udpout:127.0.0.1:14550`, QGroundControl's port)
    * `--speedup K` — run K times faster than real time (default 1; from
      0.01 to 1000, beyond which the vehicles cannot keep up: see
      `Dolphin.Clock`)
    * `--home LAT,LON,ALT` — where the fleet stands (default the report's
      40.444233,-7.375234,820; latitude -90..90, longitude -180..180,
      altitude -1000..10000 m above mean sea level); vehicles are spread 30 m apart
    * `--first-sysid N` — the first system id (default 1)
    * `--camera` — every vehicle carries a camera (component 100)
    * `--ekf-ready SECONDS` — vehicle seconds from boot until arming is possible (default 15)
    * `--battery-failsafe rtl|land|none` — what a low battery does (default none, as ArduPilot)
    * `--seed N` — seeds the faults' randomness
    * `--for SECONDS` — stop after that many seconds of vehicle time, more
      than 0 (default: until interrupted)
    * `--quiet` — no status lines

  While it runs, a status line per vehicle is printed every 10 seconds (real time).

  ## Exit status

  As every task's (README.md, "Exit status"): 0 — `--for` ended it; 1 —
  the vehicles could not be started; 2 — bad usage (an unknown option, a
  value out of range or that means nothing, such as `--for 0`: the message
  names the flag, the value and what is allowed); 130 / 143 — Ctrl-C /
  SIGTERM stopped it: the vehicles are stopped first (a second signal, a
  second later or more, exits at once).
  """

  use Mix.Task

  alias Dolphin.CLI.{Signals, Values}

  @options [
    count: :vehicles,
    gcs: {:endpoint, [:udpout]},
    speedup: :speedup,
    home: :location,
    first_sysid: :sysid,
    camera: :boolean,
    ekf_ready: :delay,
    battery_failsafe: {:one_of, %{"rtl" => :rtl, "land" => :land, "none" => :none}},
    seed: :integer,
    for: :seconds,
    quiet: :boolean
  ]

  @impl Mix.Task
  def run(argv) do
    signals? = Signals.exit_on_signal("dolphin.sim", "stopped before the vehicles started")
    # A closed pipe (`| head`) ends the task at once, quietly.
    Dolphin.CLI.Stdout.watch()

    opts =
      case parse(argv) do
        {:ok, opts} -> opts
        {:error, e} -> Mix.raise("mix dolphin.sim: #{Exception.message(e)} (see mix help dolphin.sim)", exit_status: 2)
      end

    Mix.Task.run("app.start")
    sysids = start!(opts)
    # While they fly, Ctrl-C and SIGTERM stop them in order (wait/2).
    if signals?, do: Signals.catch_signals(self())
    unless opts[:quiet], do: Mix.shell().info("simulating #{length(sysids)} vehicle(s) #{Dolphin.Fleet.VehicleSet.format(sysids)}, sending to #{opts[:gcs]}")
    wait(sysids, opts)
  end

  @doc false
  # The options, checked, as `Dolphin.Sim.start/1` takes them (plus :for and :quiet).
  @spec parse([String.t()]) :: {:ok, keyword()} | {:error, Dolphin.CommandLineError.t()}
  def parse(argv) do
    Values.parse_options(argv, @options, fn opts ->
      with {:ok, _} <- Values.sysids(Keyword.get(opts, :count, 1), Keyword.get(opts, :first_sysid, 1), "--count", "--first-sysid") do
        {:ok,
         opts
         |> Keyword.put_new(:gcs, "udpout:127.0.0.1:14550")
         |> Keyword.update(:ekf_ready, nil, &round(&1 * 1000))
         |> rename(:ekf_ready, :ekf_ready_ms)
         |> Enum.reject(fn {_k, v} -> v == nil end)}
      end
    end)
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
    until = if opts[:for], do: Dolphin.Clock.now_ms() + round(opts[:for] * 1000)
    left = fn -> if until, do: Dolphin.Clock.to_real_ms(until - Dolphin.Clock.now_ms()), else: :infinity end
    Signals.run_until(left, "the simulated vehicles", fn -> unless opts[:quiet], do: Enum.each(sysids, &status/1) end, &Dolphin.Sim.stop/0)
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

  defp rename(opts, from, to) do
    case Keyword.pop(opts, from) do
      {nil, opts} -> opts
      {value, opts} -> Keyword.put(opts, to, value)
    end
  end
end
