defmodule Mix.Tasks.Dolphin.Check do
  @shortdoc "Checks a Dolphin script before anything flies"

  @moduledoc """
  A pre-flight check of a script (`Dolphin.Check`): it compiles, runs dry
  against stand-ins for the fleet, and checks every mission it would fly,
  every pick and allocation, and each mission's battery use — before any
  vehicle is commanded.

      mix dolphin.check examples/two_vehicles.exs --sim 2
      mix dolphin.check survey.exs --fleet fleet.json --max-distance 800 --json

  One line per finding, `FILE:LINE: SEVERITY: what` (errors, then warnings,
  then notes), then one line per mission (length, time, battery use) and a
  summary.

  The script runs dry for at most an hour of clock time (a few seconds):
  what it has not reached by then is a note. A pack that would run empty
  is an error here; `mix dolphin.run --sim N`, which runs the same check
  before it flies, shows it as a warning, since simulated copters fly on at
  0 %. Severities, kinds and the estimate: `Dolphin.Check`.

  ## Options

    * `--sim N` — the fleet is N simulated ArduCopters (as `mix dolphin.run
      --sim N` starts them): UAVs with a camera, full, on the ground at the
      simulator's home (the default: `--sim 1`); N from 1 to 254, and
      beyond named as `mix dolphin.run --sim N` names them (`1@sim2`, ...)
    * `--fleet FILE` — the fleet described in a JSON file:

          {"vehicles": [{"id": 1, "type": "uav", "payloads": ["camera"],
                         "battery": 1.0, "position": [40.444233, -7.375234, 820],
                         "airborne": false}]}

      `id` (system id) and `position` (`[lat, lon, height above sea
      level]`, its home) are required; `type` (`"uav"`, `"ugv"`, `"usv"`,
      `"uuv"` or `"other"`) defaults to `"uav"`, `payloads` (names such as
      `"camera"`) to none, `battery` (0.0..1.0) to 1.0, `airborne` to false;
      a file that cannot be used is refused with every problem in it (see
      `Dolphin.Check.FleetFile`)
    * `--connect ENDPOINT` — the live fleet: the vehicles that report on
      this link (`udpin:0.0.0.0:14550`, `udpout:HOST:PORT`, `tcp:HOST:PORT`;
      repeatable) within `--wait`, as they are now (their position taken as
      their home); nothing is sent to them (`Dolphin.Check.LiveFleet`)
    * `--wait SECONDS` — how long `--connect` listens for vehicles (default
      5; more than 0)
    * `--max-distance M` — no mission item further than M metres from home
      (default 12000; more than 0)
    * `--max-height M` — no mission item higher than M metres above home
      (default 500; more than 0)
    * `--max-depth M` — no submarine's item deeper than M metres below the
      surface (default 100; more than 0)
    * `--json` — the report as one JSON object (`file`, `ok`, `findings`:
      `severity`, `kind`, `file`, `line`, `message`; `missions`: `mission`,
      `vehicle`, `line`, `length_m`, `time_s`, `battery_used`,
      `battery_start`, `ending`)

  ## Exit status

  As every task's (README.md, "Exit status"): 0 — no error (warnings and
  notes may remain); 1 — the check found errors; 2 — bad usage (an unknown
  option, a value out of range, no such script or a directory given for
  it, a bad fleet file: the message names the flag or the file, the value
  and what is allowed); with `--connect`, 1 also when the link cannot be
  opened or no vehicle reported its position in time; 130 / 143 — Ctrl-C /
  SIGTERM stopped it before it finished (never 0: an interrupted check
  found nothing).
  """

  use Mix.Task

  alias Dolphin.CLI.Values

  @options [sim: :fleet_size, fleet: :string, connect: {:keep, :endpoint}, wait: :wait, max_distance: :metres, max_height: :metres, max_depth: :metres, json: :boolean]
  @usage "usage: mix dolphin.check SCRIPT [--sim N | --fleet FILE | --connect ENDPOINT... [--wait SECONDS]] [--max-distance M] [--max-height M] [--max-depth M] [--json]"

  @impl Mix.Task
  def run(argv) do
    # An interrupted check found nothing: never the status of one that found no error.
    Dolphin.CLI.Signals.exit_on_signal("dolphin.check", "the check did not finish")
    # A closed pipe (`| head`) ends the task at once, quietly.
    Dolphin.CLI.Stdout.watch()

    case main(argv) do
      0 -> :ok
      code -> exit({:shutdown, code})
    end
  end

  @doc """
  Does the work of the task and returns the exit status. `io`: `:out` and
  `:err` (devices, default `:stdio` and `:stderr`).
  """
  @spec main([String.t()], keyword()) :: 0 | 1 | 2
  def main(argv, io \\ []) do
    out = Keyword.get(io, :out, :stdio)
    err = Keyword.get(io, :err, :stderr)

    with {:ok, file, opts} <- parse(argv),
         {:ok, check_opts} <- fleet(opts),
         {:ok, check_opts} <- live_fleet(opts, check_opts, err) do
      report = Dolphin.Check.run(file, check_opts)
      if opts[:json], do: IO.puts(out, :jiffy.encode(Dolphin.Check.to_map(report), [:pretty])), else: IO.write(out, Dolphin.Check.format(report))
      if Dolphin.Check.errors?(report), do: 1, else: 0
    else
      {:error, %Dolphin.CommandLineError{reason: :failed} = e} ->
        IO.puts(err, "mix dolphin.check: #{Exception.message(e)}")
        1

      {:error, e} ->
        IO.puts(err, "mix dolphin.check: #{Exception.message(e)}\n#{@usage}")
        2
    end
  end

  # The application is up from here (links and vehicles for --connect; the
  # dry run's fleet and pub/sub either way).
  defp live_fleet(opts, check_opts, err) do
    Mix.Task.run("app.start")

    case Keyword.get_values(opts, :connect) do
      [] ->
        {:ok, check_opts}

      endpoints ->
        with {:ok, vehicles, skipped} <- Dolphin.Check.LiveFleet.gather(endpoints, round(Keyword.get(opts, :wait, 5.0) * 1000)) do
          if skipped != [], do: IO.puts(err, "mix dolphin.check: left out (no position reported): vehicle(s) #{Enum.join(skipped, ", ")}")
          {:ok, [fleet: vehicles] ++ Keyword.drop(check_opts, [:sim])}
        end
    end
  end

  @doc false
  # The script and the options of a command line, checked.
  @spec parse([String.t()]) :: {:ok, Path.t(), keyword()} | {:error, Dolphin.CommandLineError.t()}
  def parse(argv) do
    Values.parse_script(argv, Values.switches(@options), fn file, opts ->
      with {:ok, opts} <- Values.check(opts, @options),
           :ok <- combination(opts),
           :ok <- Values.input_file(file, "script"),
           :ok <- if(opts[:fleet], do: Values.input_file(opts[:fleet], "fleet file"), else: :ok) do
        {:ok, file, opts}
      end
    end)
  end

  defp combination(opts) do
    cond do
      Enum.count([opts[:sim], opts[:fleet], opts[:connect]], & &1) > 1 -> usage_error("only one of --sim, --fleet and --connect")
      opts[:wait] != nil and opts[:connect] == nil -> usage_error("--wait goes with --connect")
      true -> :ok
    end
  end

  defp fleet(opts) do
    limits = Keyword.take(opts, [:max_distance, :max_height, :max_depth])

    case opts[:fleet] do
      nil ->
        {:ok, [sim: Keyword.get(opts, :sim, 1)] ++ limits}

      path ->
        case Dolphin.Check.FleetFile.read(path) do
          {:ok, vehicles} -> {:ok, [fleet: vehicles] ++ limits}
          {:error, e} -> {:error, e}
        end
    end
  end

  defp usage_error(message), do: Dolphin.CommandLineError.usage_error(message)
end
