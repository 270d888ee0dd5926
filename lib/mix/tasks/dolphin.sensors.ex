defmodule Mix.Tasks.Dolphin.Sensors do
  @shortdoc "Plays the companion computers of ArduPilot SITL vehicles: their sensors sense a world file"

  @moduledoc """
  Runs a sensor sidecar (`Dolphin.Sim.Sidecar`): companion computers for
  vehicles this VM does not simulate — ArduPilot SITL's, started by hand or
  by another tool — so that their sensors sense a world file
  (`Dolphin.Sim.World`, docs/simulator.md) as `--sim copter:2+smoke` does.

      arducopter --model + --serial0 udpclient:127.0.0.1:14550 --serial1 udpclient:127.0.0.1:14560 ...
      mix dolphin.sensors --world examples/worlds/serra_fire.json --connect udpin:127.0.0.1:14560

  It listens where the autopilots' second telemetry port sends
  (`--connect udpin:HOST:PORT`), or sends first to one that listens
  (`udpout:HOST:PORT`). For each autopilot it hears, it asks for its
  position and sends back, with the autopilot's system id and component
  191, a HEARTBEAT and each sensor's NAMED_VALUE_FLOAT; ArduPilot forwards
  them to its ground station. `mix dolphin.run --sitl copter:2+smoke
  --world FILE` starts one by itself.

  ## Options

    * `--world FILE` — what the sensors sense (required)
    * `--connect ENDPOINT` — `udpin:HOST:PORT` (default `udpin:127.0.0.1:14560`) or `udpout:HOST:PORT`
    * `--sensors LIST` — the sensors of every vehicle, comma-separated
      (`smoke`, `water_temp`, `range`; default `smoke`)
    * `--rate HZ` — readings a second of vehicle time (default 2, at most 50)
    * `--noise SIGMA` — the noise's standard deviation (default each model's)
    * `--seed N` — seeds the noise
    * `--for SECONDS` — stop after that many seconds (default: until interrupted)
    * `--quiet` — no status lines (one every 10 s, and at the end: the
      readings sent to each vehicle)

  ## Exit status

  As every task's (README.md, "Exit status"): 0 — `--for` ended it; 1 —
  the world file is wrong (its line and key are named) or the port cannot
  be opened; 2 — bad usage; 130 / 143 — Ctrl-C / SIGTERM stopped it.
  """

  use Mix.Task

  alias Dolphin.CLI.{Signals, Values}
  alias Dolphin.Sim.{Companion, Sidecar, World}

  @options [
    world: {:file, "world file"},
    connect: {:endpoint, [:udpin, :udpout]},
    sensors: :string,
    rate: :speed,
    noise: :string,
    seed: :integer,
    for: :seconds,
    quiet: :boolean
  ]

  @impl Mix.Task
  def run(argv) do
    signals? = Signals.exit_on_signal("dolphin.sensors", "stopped before the sidecar started")
    Dolphin.CLI.Stdout.watch()

    opts =
      case parse(argv) do
        {:ok, opts} -> opts
        {:error, e} -> Mix.raise("mix dolphin.sensors: #{Exception.message(e)} (see mix help dolphin.sensors)", exit_status: 2)
      end

    world =
      case World.read(opts[:world]) do
        {:ok, world} -> world
        {:error, why} -> Mix.raise("mix dolphin.sensors: --world: #{why}")
      end

    Mix.Task.run("app.start")
    {:ok, endpoint} = Dolphin.Link.Endpoint.parse(opts[:connect])
    where = if endpoint.kind == :udpin, do: [listen: {endpoint.address, endpoint.port}], else: [connect: {endpoint.address, endpoint.port}]
    sidecar_opts = [sensors: opts[:sensors], world: world, rate_hz: opts[:rate], noise: opts[:noise], seed: opts[:seed]]

    pid =
      case Sidecar.start_link(where ++ Enum.reject(sidecar_opts, fn {_, v} -> v == nil end)) do
        {:ok, pid} -> pid
        {:error, {:cannot_open, what, why}} -> Mix.raise("mix dolphin.sensors: #{what}: #{why}")
      end

    if signals?, do: Signals.catch_signals(self())
    unless opts[:quiet], do: Mix.shell().info("sensor sidecar on #{opts[:connect]}: #{Enum.join(opts[:sensors], ", ")} for every vehicle heard, sensing #{opts[:world]}")
    until = if opts[:for], do: System.monotonic_time(:millisecond) + round(opts[:for] * 1000)
    left = fn -> if until, do: until - System.monotonic_time(:millisecond), else: :infinity end
    status = fn -> unless opts[:quiet], do: status(pid) end
    Signals.run_until(left, "the sensor sidecar", status, fn ->
      status.()
      Sidecar.stop(pid)
    end)
  end

  @doc false
  # The options, checked; --sensors as a list of models.
  @spec parse([String.t()]) :: {:ok, keyword()} | {:error, Dolphin.CommandLineError.t()}
  def parse(argv) do
    Values.parse_options(argv, @options, fn opts ->
      with :ok <- required(opts),
           {:ok, sensors} <- sensors(Keyword.get(opts, :sensors, "smoke")),
           :ok <- rate(opts[:rate]),
           {:ok, noise} <- noise(opts[:noise]) do
        {:ok, opts |> Keyword.put(:sensors, sensors) |> Keyword.put(:noise, noise) |> Keyword.put_new(:connect, "udpin:127.0.0.1:14560")}
      end
    end)
  end

  defp required(opts), do: if(opts[:world], do: :ok, else: Dolphin.CommandLineError.usage_error("--world FILE is required: what the sensors sense"))

  defp sensors(text) do
    names = String.split(text, ",", trim: true)
    known = Enum.map(Companion.models(), &Atom.to_string/1)

    case Enum.find(names, &(&1 not in known)) do
      nil when names != [] -> {:ok, Enum.map(names, &String.to_existing_atom/1)}
      nil -> Dolphin.CommandLineError.usage_error("--sensors #{text}: at least one of #{Enum.join(known, ", ")}")
      name -> Dolphin.CommandLineError.usage_error("--sensors #{text}: no simulated sensor #{inspect(name)}: the simulator's sensors are #{Enum.join(known, ", ")}")
    end
  end

  defp noise(nil), do: {:ok, nil}

  defp noise(text) do
    case Float.parse(text) do
      {sigma, ""} when sigma >= 0 -> {:ok, sigma}
      _ -> Dolphin.CommandLineError.usage_error("--noise #{text}: the noise's standard deviation, a number 0 or more")
    end
  end

  defp rate(nil), do: :ok
  defp rate(hz) when hz <= 50, do: :ok
  defp rate(hz), do: Dolphin.CommandLineError.usage_error("--rate #{hz}: readings a second, more than 0 and at most 50")

  defp status(pid) do
    case Sidecar.vehicles(pid) do
      none when none == %{} -> Mix.shell().info("no vehicle heard yet")
      vehicles -> Enum.each(Enum.sort(vehicles), fn {id, sent} -> Mix.shell().info("vehicle #{id}: #{sent} readings sent") end)
    end
  end
end
