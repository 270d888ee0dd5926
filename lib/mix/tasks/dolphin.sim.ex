defmodule Mix.Tasks.Dolphin.Sim do
  @shortdoc "Runs simulated ArduCopters for any ground station to fly"

  @moduledoc """
  Runs the built-in simulator alone, so that any ground station
  (QGroundControl, MAVProxy, a pymavlink script, or another Dolphin) can fly it.

      mix dolphin.sim --count 3 --gcs udpout:127.0.0.1:14550 --speedup 5

  Each vehicle sends from its own UDP port to the ground station's endpoint, as
  ArduPilot SITL's `--serial0 udpclient:HOST:PORT` does; system ids are 1..N.

  A fleet of more than 254 vehicles is several *networks* (radios), each
  with system ids of its own, as fleets of vehicles that all left the
  factory as system id 1 are:

      mix dolphin.sim --count 2000 --networks 8 --gcs udpout:127.0.0.1:14550

  sends from 8 networks of 250 vehicles, system ids 1..250 on each, the
  first network to port 14550, the second to 14551, and so on; a ground
  station listens on each (`mix dolphin.run --connect udpin:0.0.0.0:14550
  --connect udpin:0.0.0.0:14551 ...`), or on one port for all of them (each
  vehicle sends from an address of its own: one `udpin` link tells them
  apart, see `Dolphin.Vehicles.Id`).

  ## Options

    * `--count N` — how many vehicles (default 1; with `--first-sysid`,
      their system ids must fit in 1..254 on each network)
    * `--networks K` — spread them over K networks (default 1, at most
      64): the vehicles split evenly, each network numbered from
      `--first-sysid` and sending to the port after the previous one's
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

  While it runs, a status line per vehicle is printed every 10 seconds (real
  time); for more than #{10} vehicles, one line that counts them by what they
  are doing. When it ends, a line says how many frames the vehicles sent.

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
    count: :fleet_size,
    networks: {:range, 1..64, "a number of networks from 1 to 64"},
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
    unless opts[:quiet], do: Mix.shell().info("simulating #{length(sysids)} vehicle(s) #{fleet_text(sysids)}, sending to #{gcs_text(opts)}")
    wait(sysids, opts)
  end

  defp fleet_text(ids) do
    case Enum.group_by(ids, &network/1, &sysid/1) do
      %{nil: sysids} -> Dolphin.Fleet.VehicleSet.format(sysids)
      networks -> "over #{map_size(networks)} networks, system ids #{range_text(Map.values(networks))} on each"
    end
  end

  defp range_text(groups) do
    {small, large} = groups |> Enum.map(&Enum.min_max/1) |> Enum.min_max_by(fn {a, b} -> b - a end)
    if small == large, do: "#{elem(small, 0)}..#{elem(small, 1)}", else: "#{elem(small, 0)}..#{elem(small, 1)} or #{elem(large, 0)}..#{elem(large, 1)}"
  end

  defp gcs_text(opts) do
    case opts[:networks] do
      n when n in [nil, 1] ->
        opts[:gcs]

      n ->
        {:ok, %{address: address, port: port}} = Dolphin.Link.Endpoint.parse(opts[:gcs])
        "#{:inet.ntoa(address)}:#{port}..#{port + n - 1}, a port per network"
    end
  end

  defp network({network, _sysid}), do: network
  defp network(_sysid), do: nil
  defp sysid({_network, sysid}), do: sysid
  defp sysid(sysid), do: sysid

  @doc false
  # The options, checked, as `Dolphin.Sim.start/1` takes them (plus :for and :quiet).
  @spec parse([String.t()]) :: {:ok, keyword()} | {:error, Dolphin.CommandLineError.t()}
  def parse(argv) do
    Values.parse_options(argv, @options, fn opts ->
      with {:ok, _} <- Values.networks(Keyword.get(opts, :count, 1), Keyword.get(opts, :networks, 1), Keyword.get(opts, :first_sysid, 1)),
           :ok <- gcs_ports(opts) do
        {:ok,
         opts
         |> Keyword.put_new(:gcs, "udpout:127.0.0.1:14550")
         |> Keyword.update(:ekf_ready, nil, &round(&1 * 1000))
         |> rename(:ekf_ready, :ekf_ready_ms)
         |> Enum.reject(fn {_k, v} -> v == nil end)}
      end
    end)
  end

  # Each network's port after the previous one's: the last one must be a port.
  defp gcs_ports(opts) do
    with n when is_integer(n) and n > 1 <- opts[:networks],
         {:ok, %{port: port}} <- Dolphin.Link.Endpoint.parse(Keyword.get(opts, :gcs, "udpout:127.0.0.1:14550")),
         true <- port + n - 1 > 65_535 do
      Dolphin.CommandLineError.usage_error("--networks #{n} with --gcs #{opts[:gcs]}: the networks send to ports #{port}..#{port + n - 1}, beyond 65535")
    else
      _ -> :ok
    end
  end

  @doc false
  def start!(opts) do
    camera = if opts[:camera], do: [camera: true], else: []
    sim_opts = Keyword.drop(opts, [:for, :quiet, :camera, :networks, :count, :first_sysid]) ++ camera

    case Keyword.get(opts, :networks, 1) do
      1 ->
        started!(Dolphin.Sim.start(sim_opts ++ Keyword.take(opts, [:count, :first_sysid])))

      n ->
        # The whole fleet spread around its home once, the networks side by side in it.
        {:ok, %{address: address, port: port}} = Dolphin.Link.Endpoint.parse(opts[:gcs])
        count = Keyword.get(opts, :count, 1)
        first = Keyword.get(opts, :first_sysid, 1)
        homes = Dolphin.Sim.homes(count, Keyword.take(opts, [:home]))
        sizes = for k <- 0..(n - 1), do: div(count, n) + if(k < rem(count, n), do: 1, else: 0)

        {ids, []} =
          sizes
          |> Enum.with_index(1)
          |> Enum.flat_map_reduce(homes, fn {size, k}, homes ->
            {mine, rest} = Enum.split(homes, size)
            network_opts = [gcs: {address, port + k - 1}, network: k, count: size, first_sysid: first, homes: mine]
            {started!(Dolphin.Sim.start(Keyword.drop(sim_opts, [:gcs, :home]) ++ network_opts)), rest}
          end)

        ids
    end
  end

  defp started!({:ok, ids}), do: ids

  defp started!({:error, e}) do
    Dolphin.Sim.stop()
    Mix.raise("mix dolphin.sim: #{Exception.message(e)}")
  end

  defp wait(sysids, opts) do
    until = if opts[:for], do: Dolphin.Clock.now_ms() + round(opts[:for] * 1000)
    left = fn -> if until, do: Dolphin.Clock.to_real_ms(until - Dolphin.Clock.now_ms()), else: :infinity end

    stop = fn ->
      sent =
        sysids
        |> infos()
        |> Enum.reduce(0, fn
          {:ok, i}, n -> n + i.sent
          _gone, n -> n
        end)

      Dolphin.Sim.stop()
      unless opts[:quiet], do: Mix.shell().info("the #{length(sysids)} vehicle(s) sent #{sent} frames")
    end

    Signals.run_until(left, "the simulated vehicles", fn -> unless opts[:quiet], do: status(sysids) end, stop)
  end

  @listed 10
  @info_timeout_ms 5_000

  defp status(ids) when length(ids) <= @listed, do: Enum.each(ids, &vehicle_status/1)

  # A large fleet: one line that counts the vehicles by mode and state.
  defp status(ids) do
    answers = infos(ids)
    infos = for {:ok, i} <- answers, do: i
    groups = infos |> Enum.frequencies_by(&"#{&1.mode}#{if &1.armed, do: " armed", else: ""} #{&1.landed}") |> Enum.sort_by(fn {text, n} -> {-n, text} end)
    lag = infos |> Enum.map(& &1.lag_ms) |> Enum.max(fn -> 0 end)
    gone = Enum.count(answers, &(&1 == {:error, :unknown_vehicle}))
    busy = Enum.count(answers, &(&1 == {:error, :busy}))

    Mix.shell().info(
      "#{length(infos)} vehicles: " <>
        Enum.map_join(groups, ", ", fn {text, n} -> "#{n} #{text}" end) <>
        "; the furthest behind the clock by #{lag} ms" <>
        if(gone > 0, do: "; #{gone} gone", else: "") <> if(busy > 0, do: "; #{busy} too busy to answer within #{div(@info_timeout_ms, 1000)} s", else: "")
    )
  end

  # Each vehicle's info, asked of many at once; a vehicle too busy to answer
  # in time (a fleet larger than the host can fly) is said to be, and never
  # ends the simulation.
  defp infos(ids) do
    ids
    |> Task.async_stream(&info/1, max_concurrency: 64, timeout: @info_timeout_ms + 1_000, on_timeout: :kill_task)
    |> Enum.map(fn
      {:ok, answer} -> answer
      {:exit, _} -> {:error, :busy}
    end)
  end

  defp info(id) do
    Dolphin.Sim.info(id)
  catch
    :exit, _ -> {:error, :busy}
  end

  defp vehicle_status(id) do
    name = if network(id), do: "vehicle #{sysid(id)} of network #{network(id)}", else: "vehicle #{id}"

    case info(id) do
      {:ok, i} ->
        p = i.position

        Mix.shell().info(
          "#{name}: #{i.mode}#{if i.armed, do: " armed", else: ""} #{i.landed} " <>
            "#{Float.round(p.lat, 6)},#{Float.round(p.lon, 6)} #{Float.round(p.relative_alt, 1)} m " <>
            "battery #{round(i.battery * 100)} % mission #{i.current}/#{length(i.mission)} photos #{i.photos}"
        )

      {:error, :unknown_vehicle} ->
        Mix.shell().info("#{name}: gone")

      {:error, :busy} ->
        Mix.shell().info("#{name}: too busy to answer within #{div(@info_timeout_ms, 1000)} s")
    end
  end

  defp rename(opts, from, to) do
    case Keyword.pop(opts, from) do
      {nil, opts} -> opts
      {value, opts} -> Keyword.put(opts, to, value)
    end
  end
end
