defmodule Mix.Tasks.Dolphin.Station do
  @shortdoc "Runs a ground-station node of a cluster: links and vehicles, no script"

  @moduledoc """
  Runs a ground station that other nodes join (`Dolphin.Cluster`): it opens
  its links, hears its vehicles and serves them to every controller that
  joins it (`mix dolphin.run SCRIPT --join NODE`, `mix dolphin.console
  --join NODE`), until it is stopped (Ctrl-C or SIGTERM). It prints the
  vehicles it hears as they come and go.

      mix dolphin.station --sname gs1 --connect udpin:0.0.0.0:14550
      mix dolphin.station --sname gs1 --cookie secret --sim 3 --speedup 10
      mix dolphin.station --name gs2@10.0.0.2 --cookie secret --connect udpin:0.0.0.0:14551

  ## Options

    * `--sname NAME` or `--name NAME@HOST` (one is required) — the node's
      name, short or long (as `erl -sname` / `-name`); controllers join it
      by this name
    * `--cookie C` — the cluster's cookie (else `~/.erlang.cookie`)
    * `--connect ENDPOINT` — a link to vehicles (`udpin:0.0.0.0:14550`,
      `udpout:HOST:PORT`, `tcp:HOST:PORT`); repeatable
    * `--sim N` — also start N simulated vehicles (`Dolphin.Sim`) on a local
      link, with system ids from `--first-sysid` (default 1): give each
      station of one machine its own range (within 1..254)
    * `--speedup K` — run K times faster than real time (0.01 to 1000, see
      `Dolphin.Clock`); every node of the
      cluster runs at the same speed-up (a controller adopts it)
    * `--seed N` — the simulator's seed
    * `--tlog FILE` — record every MAVLink frame of the links (an existing
      FILE is replaced)

  With neither `--connect` nor `--sim`, the station listens on
  `Dolphin.Link.default_endpoint/0`.

  ## Exit status

  As every task's (README.md, "Exit status"): 1 — it could not start
  (distribution, a port in use); 2 — bad usage (no `--sname`/`--name`, an
  unknown option, a value out of range: the message names the flag, the
  value and what is allowed); 130 — Ctrl-C stopped it; 143 — SIGTERM did
  (its links and vehicles stopped first; a second signal, a second later or
  more, ends it at once).
  """

  use Mix.Task

  alias Dolphin.CLI.{Signals, Teardown, Values}

  @options [
    sname: :string,
    name: :string,
    cookie: :string,
    connect: {:keep, :endpoint},
    sim: :vehicles,
    first_sysid: :sysid,
    speedup: :speedup,
    seed: :integer,
    tlog: :output
  ]

  @usage "usage: mix dolphin.station (--sname NAME | --name NAME@HOST) [--cookie C] [--connect ENDPOINT]... [--sim N [--first-sysid ID]] [--speedup K] [--seed N] [--tlog FILE]"

  @impl Mix.Task
  def run(argv) do
    signals? = Signals.exit_on_signal("dolphin.station", "stopped before the station started")
    # A closed pipe (`| head`) ends the task at once, quietly.
    Dolphin.CLI.Stdout.watch()

    case main(argv, signals: signals?) do
      0 -> :ok
      code -> exit({:shutdown, code})
    end
  end

  @doc """
  Does the work of the task and returns the exit status. `io` options:
  `:out`, `:err` (devices), `:signals` (SIGINT and SIGTERM stop the
  station, with their status), `:ready` (a pid told `{Mix.Tasks.Dolphin.Station, :ready,
  node}` once the station runs). The station also stops on a
  `{Mix.Tasks.Dolphin.Station, :stop}` message to the calling process.
  """
  @spec main([String.t()], keyword()) :: 0 | 1 | 2 | 130 | 143
  def main(argv, io \\ []) do
    out = Keyword.get(io, :out, :stdio)
    err = Keyword.get(io, :err, :stderr)

    case parse(argv) do
      {:ok, opts} ->
        Mix.Task.run("app.start")
        serve(opts, io, out, err)

      {:error, e} ->
        IO.puts(err, "mix dolphin.station: #{Exception.message(e)}\n#{@usage}")
        2
    end
  end

  @doc false
  # The options of a command line, checked.
  @spec parse([String.t()]) :: {:ok, keyword()} | {:error, Dolphin.CommandLineError.t()}
  def parse(argv) do
    Values.parse_options(
      argv,
      @options,
      fn opts ->
        cond do
          opts[:sname] == nil and opts[:name] == nil -> Dolphin.CommandLineError.usage_error("a station needs a node name: give --sname NAME or --name NAME@HOST")
          (problem = Dolphin.CLI.Cluster.check(opts)) != :ok -> Dolphin.CommandLineError.usage_error(elem(problem, 1))
          opts[:first_sysid] != nil and opts[:sim] == nil -> Dolphin.CommandLineError.usage_error("--first-sysid goes with --sim")
          opts[:sim] != nil -> with({:ok, _} <- Values.sysids(opts[:sim], Keyword.get(opts, :first_sysid, 1), "--sim", "--first-sysid"), do: {:ok, opts})
          true -> {:ok, opts}
        end
      end,
      &"unexpected argument #{inspect(&1)} (a station runs no script: mix dolphin.run SCRIPT --join NODE does)"
    )
  end

  defp serve(opts, io, out, err) do
    previous = Dolphin.Clock.speedup()
    if k = opts[:speedup], do: Dolphin.Clock.set_speedup(k)
    Teardown.begin()
    Dolphin.Vehicles.subscribe(:all)
    # Caught until its links and vehicles are stopped: one that comes while
    # it starts stops it once started (wait/1); a second one, later, ends it at once.
    if io[:signals], do: Signals.catch_signals(self())

    try do
      with {:ok, lines} <- Dolphin.CLI.Cluster.start(opts, nil),
           {:ok, log} <- start_tlog(opts[:tlog]),
           {:ok, more} <- links(opts),
           {:ok, sims} <- sims(opts) do
        k = Dolphin.Clock.speedup()
        IO.puts(out, "ground station #{node()} (#{if k == 1, do: "real time", else: "speed-up #{Dolphin.Console.Format.num(k / 1)}x"}); Ctrl-C stops it")
        Enum.each(Enum.drop(lines, 1) ++ more ++ sims ++ log, &IO.puts(out, "  " <> &1))
        if pid = io[:ready], do: send(pid, {__MODULE__, :ready, node()})
        wait(out)
      else
        {:error, e} ->
          IO.puts(err, "mix dolphin.station: #{Exception.message(e)}")
          1
      end
    after
      Dolphin.PubSub.unsubscribe(:vehicles)
      Teardown.run_all()
      Dolphin.Clock.set_speedup(previous)
      if io[:signals], do: Signals.release_signals()
    end
  end

  # Until stopped, the vehicles as they come and go.
  defp wait(out) do
    receive do
      {:dolphin, :vehicles, {event, id}} ->
        if event in [:vehicle_discovered, :vehicle_lost, :vehicle_reconnected, :vehicle_forgotten],
          do: IO.puts(out, "vehicle #{id} #{event |> Atom.to_string() |> String.replace_prefix("vehicle_", "")}")

        wait(out)

      {:dolphin_signal, sig} ->
        IO.puts(out, "#{Signals.name(sig)}: the station stops")
        Signals.status(sig)

      {__MODULE__, :stop} ->
        IO.puts(out, "the station stops")
        0
    end
  end

  # The links append to the log; emptied first, it holds this station's run only.
  defp start_tlog(nil), do: {:ok, []}

  defp start_tlog(path) do
    with {:ok, line} <- Dolphin.CLI.OutputFile.start_log(path), do: {:ok, [line]}
  end

  defp links(opts) do
    endpoints = Keyword.get_values(opts, :connect)
    endpoints = if endpoints == [] and opts[:sim] == nil, do: [Dolphin.Link.default_endpoint()], else: endpoints
    link_opts = if opts[:tlog], do: [tlog: opts[:tlog]], else: []

    with :ok <- Dolphin.CLI.Vehicles.connect_all(endpoints, link_opts, &defer/1), do: {:ok, Enum.map(endpoints, &"link #{&1}")}
  end

  defp sims(opts) do
    case opts[:sim] do
      nil ->
        {:ok, []}

      n ->
        link_opts = if opts[:tlog] && opts[:connect] == nil, do: [tlog: opts[:tlog]], else: []
        sim_opts = [seed: Keyword.get(opts, :seed, 1), first_sysid: Keyword.get(opts, :first_sysid, 1)] ++ link_opts

        case Dolphin.Sim.Local.start(n, sim_opts) do
          {:ok, sim} ->
            defer(fn -> Dolphin.Sim.Local.stop(sim) end)
            {:ok, ["#{n} simulated vehicle(s) #{Dolphin.Sim.Local.describe(sim)}"]}

          {:error, e} ->
            {:error, Dolphin.CommandLineError.failed(nil, e)}
        end
    end
  end

  defp defer(fun), do: Teardown.defer(fun)
end
