defmodule Mix.Tasks.Dolphin.Console do
  @shortdoc "Starts Dolphin with no script, for an IEx console (iex -S mix dolphin.console)"

  @moduledoc """
  Starts the ground station with no script, for the IEx console helpers of
  `Dolphin.Console`:

      iex -S mix dolphin.console --sim 2 --speedup 20
      iex -S mix dolphin.console --connect udpin:0.0.0.0:14550
      iex -S mix dolphin.console --connect tcp:127.0.0.1:5760 --forward udpout:127.0.0.1:14551

  It opens the links (or starts simulated vehicles on a local link), waits
  until the simulated vehicles are known, prints a short banner and returns:
  IEx takes over, with the helpers imported by the project's `.iex.exs`
  (`vehicles()`, `tasks()`, `run("script.exs")`, `takeoff(1, 20)`, ... —
  `h Dolphin.Console` lists them). The links and vehicles live until IEx
  ends.

  Run without IEx (`mix dolphin.console`), it starts nothing and says to use
  `iex -S mix dolphin.console`.

  Bad usage (an unknown option, a value out of range) stops it with a
  message that names the flag, the value and what is allowed, and exit
  status 2.

  ## Options

    * `--connect ENDPOINT` — a link to vehicles (`udpin:0.0.0.0:14550`,
      `udpout:HOST:PORT`, `tcp:HOST:PORT`); repeatable
    * `--sim N` — start N simulated vehicles (`Dolphin.Sim`: ArduCopters with
      a camera) on a local link (127.0.0.1); N from 1 to 254, as for `--sitl`,
      and beyond on more networks (`SYSID@sim2`, ...: as for `mix dolphin.run`);
      `--sim copter:1,boat:1,sub:2` those airframes (as for `mix dolphin.run`)
    * `--sitl N` — start N ArduCopter SITL instances (`Dolphin.SITL`) on a
      local link (`--sitl plane:1,boat:2,sub:3`: those airframes, as for
      `mix dolphin.run`); `--sitl-bin PATH` and `--sitl-defaults FILE` as for
      `mix dolphin.run`; they stop with the VM
    * `--fleet FILE` — a fleet file (`Dolphin.Check.FleetFile`, the JSON file
      `mix dolphin.check --fleet` reads): each vehicle it lists carries its
      `payloads` (those MAVLink cannot announce: `"sidescan"`, `"smoke"`), by
      system id, for `pick(payload: ...)` (a vehicle needs no `position`
      there: it reports its own)
    * `--home LAT,LON[,ALT]` — where `--sim` and `--sitl` vehicles start
      (around that point, 30 m apart; default the report's, in Serra da
      Estrela; a submarine starts at the surface)
    * `--seed N` — the simulator's seed
    * `--speedup K` — run K times faster than real time (`Dolphin.Clock`),
      from 0.01 to 1000
    * `--tlog FILE` — record every MAVLink frame of the links to a telemetry log
      (an existing FILE is replaced)
    * `--forward ENDPOINT` — copy all traffic to a `udpout` endpoint
      (QGroundControl); repeatable

    * `--sname NAME`, `--name NAME@HOST`, `--cookie C` — make this a node of a
      cluster of ground stations (or start IEx itself with `iex --sname op`)
    * `--join NODE` — see the vehicles of the ground station `NODE` (`mix
      dolphin.station`) too, as one fleet (`Dolphin.Cluster`); repeatable:

          iex --sname op -S mix dolphin.console --join gs1@myhost --join gs2@myhost

  With neither `--connect` nor `--sim` (nor `--join`), the links of the configuration are
  used (`config :dolphin, links: [...]`), or if there are none the ground
  station listens on `Dolphin.Link.default_endpoint/0` (`udpin:0.0.0.0:14550`).

  ## Exit status

  As every task's (README.md, "Exit status"): 1 — the links or vehicles
  could not be started; 2 — bad usage (an unknown option, a bad value, run
  without IEx). In the console, Ctrl-C and SIGTERM keep IEx's meanings
  (the BREAK menu; the VM stops).
  """

  use Mix.Task

  alias Dolphin.CommandLineError

  @options Dolphin.CLI.Values.fleet_options() ++ Dolphin.CLI.Cluster.switches()

  @usage "usage: iex -S mix dolphin.console [--connect ENDPOINT]... [--sim N | --sitl N|AIRFRAME:N,...] [--fleet FILE] [--world FILE] [--home LAT,LON] [--speedup K] [--seed N]  [--tlog FILE] [--forward ENDPOINT]... [--sname NAME | --name NAME@HOST] [--cookie C] [--join NODE]..."

  @impl Mix.Task
  def run(argv) do
    # Outside IEx (where Ctrl-C and SIGTERM keep IEx's meanings) it only says how to start it.
    Dolphin.CLI.Signals.exit_on_signal("dolphin.console", "stopped before the console started")

    opts =
      case parse(argv) do
        {:ok, opts} -> opts
        {:error, error} -> Mix.raise("mix dolphin.console: #{Exception.message(error)}\n#{@usage}", exit_status: 2)
      end

    unless iex?(), do: Mix.raise("mix dolphin.console starts a console for IEx: run it as `iex -S mix dolphin.console #{Enum.join(argv, " ")}`", exit_status: 2)

    Mix.Task.run("app.start")

    case start(opts) do
      {:ok, banner} -> Mix.shell().info(banner)
      {:error, error} -> Mix.raise("mix dolphin.console: #{Exception.message(error)}")
    end
  end

  defp iex?, do: Code.ensure_loaded?(IEx) and IEx.started?()

  @doc false
  # {:ok, opts} | {:error, %CommandLineError{reason: :usage}} (run/1 adds the usage line)
  @spec parse([String.t()]) :: {:ok, keyword()} | {:error, CommandLineError.t()}
  def parse(argv) do
    case check(argv) do
      {:ok, opts} -> {:ok, opts}
      {:error, message} -> {:error, %CommandLineError{reason: :usage, message: message}}
    end
  end

  defp check(argv) do
    case OptionParser.parse(argv, strict: Dolphin.CLI.Values.switches(@options)) do
      {opts, [], []} ->
        case Dolphin.CLI.Values.check(opts, @options) do
          {:ok, opts} ->
            cond do
              opts[:sim] != nil and opts[:sitl] != nil -> {:error, "--sim and --sitl do not go together"}
              opts[:world] != nil and opts[:sim] == nil and opts[:sitl] == nil -> {:error, "--world is what simulated sensors sense: it goes with --sim or --sitl"}
              # `iex --sname op -S mix dolphin.console --join ...`: the node has its name already.
              (problem = Dolphin.CLI.Cluster.check(opts, Node.alive?())) != :ok -> problem
              true -> {:ok, opts}
            end

          {:error, e} ->
            {:error, Exception.message(e)}
        end

      {_, [arg | _], []} ->
        {:error, "unexpected argument #{inspect(arg)} (the console runs no script: run(\"script.exs\") in it does)"}

      {_, _, [{switch, value} | _]} ->
        {:error, "bad option #{switch}#{if value, do: " " <> value, else: ""}"}
    end
  end

  @doc """
  Opens the links and starts the simulated vehicles of `opts` (parsed
  options) in the running application; returns the banner to print, or a
  `Dolphin.CommandLineError` whose `cause` is the link's or the simulator's error.
  """
  @spec start(keyword()) :: {:ok, String.t()} | {:error, CommandLineError.t()}
  def start(opts) do
    if k = opts[:speedup], do: Dolphin.Clock.set_speedup(k)
    link_opts = Enum.reject([tlog: opts[:tlog], forward: Keyword.get_values(opts, :forward)], fn {_, v} -> v in [nil, []] end)
    endpoints = Keyword.get_values(opts, :connect)

    with {:ok, log} <- start_tlog(opts[:tlog]),
         {:ok, cluster} <- join(opts),
         {:ok, lines} <- connect_all(endpoints, link_opts),
         {:ok, more} <- vehicles(opts, endpoints, link_opts) do
      {:ok, banner(cluster ++ lines ++ more ++ log)}
    end
  end

  # The links append to the log; emptied first, it holds this session only.
  defp start_tlog(nil), do: {:ok, []}

  defp start_tlog(path) do
    with {:ok, line} <- Dolphin.CLI.OutputFile.start_log(path), do: {:ok, [line]}
  end

  # --sname/--name and --join (Dolphin.Cluster): the joined stations' vehicles are the console's too.
  defp join(opts) do
    case Dolphin.CLI.Cluster.start(opts, opts[:speedup]) do
      {:ok, lines} -> {:ok, lines}
      {:error, e} -> {:error, %CommandLineError{reason: :failed, message: Exception.message(e), cause: e}}
    end
  end

  defp vehicles(opts, endpoints, link_opts) do
    with {:ok, fleet_lines} <- fleet_payloads(opts[:fleet]),
         {:ok, lines} <- start_vehicles(opts, endpoints, link_opts),
         do: {:ok, fleet_lines ++ lines}
  end

  # What the fleet file says each vehicle carries (for the session's life).
  defp fleet_payloads(nil), do: {:ok, []}

  defp fleet_payloads(path) do
    with {:ok, vehicles} <- Dolphin.CLI.Vehicles.fleet_file(path) do
      given = for %{id: id, payloads: payloads} <- vehicles, payloads != [], do: Dolphin.Vehicles.put_payloads(id, payloads)
      {:ok, ["payloads of #{length(given)} vehicle(s) from #{path}"]}
    end
  end

  defp start_vehicles(opts, endpoints, link_opts) do
    cond do
      n = opts[:sim] -> start_sim(n, opts, link_opts)
      n = opts[:sitl] -> start_sitl(n, opts, link_opts)
      # Joined stations bring the vehicles: no default link then.
      endpoints != [] or opts[:join] != nil or Application.get_env(:dolphin, :links, []) != [] -> {:ok, []}
      true -> connect_all([Dolphin.Link.default_endpoint()], link_opts)
    end
  end

  defp connect_all(endpoints, link_opts) do
    Enum.reduce_while(endpoints, {:ok, []}, fn ep, {:ok, lines} ->
      case Dolphin.Link.connect(ep, link_opts) do
        {:ok, _pid} -> {:cont, {:ok, lines ++ ["link #{ep}"]}}
        {:error, e} -> {:halt, {:error, %CommandLineError{reason: :failed, message: "--connect #{ep}: #{Exception.message(e)}", cause: e}}}
      end
    end)
  end

  defp start_sim(n, opts, link_opts) do
    # The console's simulated fleet lives as long as the VM.
    with {:ok, world} <- Dolphin.CLI.Vehicles.world(opts[:world]) do
      case Dolphin.Sim.Local.start(n, [seed: Keyword.get(opts, :seed, 1), home: opts[:home], world: world] ++ link_opts) do
        {:ok, sim} -> {:ok, ["#{Dolphin.CLI.Vehicles.sim_words(n)} #{Dolphin.Sim.Local.describe(sim)}"]}
        {:error, e} -> {:error, %CommandLineError{reason: :failed, message: Exception.message(e), cause: e}}
      end
    end
  end

  defp start_sitl(n, opts, link_opts) do
    # Like the simulated fleet, the console's SITL instances live as long as the VM.
    sitl_opts = [bin: opts[:sitl_bin], defaults: Keyword.get_values(opts, :sitl_defaults), home: opts[:home]] ++ link_opts

    case Dolphin.CLI.Vehicles.sitl_fleet(n, sitl_opts, opts, fn _undo -> :ok end) do
      {:ok, fleet, lines} -> {:ok, lines ++ ["#{Dolphin.CLI.Vehicles.sitl_words(n)}, vehicles #{Enum.join(fleet.sysids, ", ")}, on 127.0.0.1:#{fleet.port}"]}
      {:error, e} -> {:error, e}
    end
  end

  defp banner(lines) do
    k = Dolphin.Clock.speedup()
    speed = if k == 1, do: "real time", else: "speed-up #{Dolphin.Console.Format.num(k / 1)}x"

    Enum.join(
      ["Dolphin console (#{speed})" | Enum.map(lines, &("  " <> &1))] ++
        [
          "Helpers (imported by .iex.exs; h Dolphin.Console for all): vehicles() tasks() run(\"script.exs\") stop(id) stop_all()",
          "  arm(id) takeoff(id, alt) goto(id, lat, lon, alt) hold(id) land(id) rtl(id) mode(id, :guided) watch(id) messages(id) events(20)"
        ],
      "\n"
    )
  end
end
