defmodule Mix.Tasks.Dolphin.Run do
  @shortdoc "Runs a Dolphin script against real, simulated or fake vehicles"

  @moduledoc """
  Runs a Dolphin script (see `Dolphin.Script`).

      mix dolphin.run examples/single_vehicle.exs --sim 1 --speedup 50
      mix dolphin.run survey.exs --connect udpin:0.0.0.0:14550 --events run.jsonl --tlog run.tlog
      mix dolphin.run logic.exs --fake 3 --for 10m

  The script is read and compiled first: a syntax error or an unknown word is
  reported with file and line before anything is sent to a vehicle. With
  `--sim N` or `--sitl N` the pre-flight check of `mix dolphin.check` runs
  next, against N simulated copters, and the run refuses to fly (exit 1) if
  it finds errors (`Dolphin.CLI.Run.check/3`; `--no-check` skips it).

  Under IEx (`iex -S mix dolphin.run SCRIPT ...`) the script runs in the
  background and the console stays usable: `Dolphin.Console`'s `vehicles()`,
  `tasks()`, `stop/1`, and `answer/1` for the script's `ask`.

  ## Options

    * `--connect ENDPOINT` — a link to vehicles (`udpin:0.0.0.0:14550`,
      `udpout:HOST:PORT`, `tcp:HOST:PORT`); repeatable
    * `--sim N` — start N simulated vehicles (`Dolphin.Sim`: ArduCopters with a
      camera) on a local link; N from 1 to 254 (one system id each), as for
      `--sitl` and `--fake`, and beyond on more networks of 254, a local
      link each, whose vehicles are named `SYSID@sim2`, `SYSID@sim3`, ... (up
      to 16,256: `Dolphin.Sim.Local`; on two cores a thousand keep up at 1x);
      `--sim copter:2,plane:1,rover:1,boat:1,sub:3`
      those airframes (ArduPlane's planes, ArduRover's rovers and boats,
      ArduSub's submarines), system ids in that order
    * `--sitl N` — start N ArduCopter SITL instances (`Dolphin.SITL`: ArduPilot's
      own flight code) on a local link, at the run's speed-up; `--sitl
      plane:1,boat:2,sub:3` starts those airframes (copter, plane, rover,
      boat, sub: ArduCopter, ArduPlane, ArduRover, ArduSub), system ids in
      that order; the other firmwares' binaries are looked for in
      `$ARDUPILOT_SITL_DIR`, beside the copter's, then in `../shared/sitl/`
    * `--sitl-bin PATH` — the SITL binary (else `$ARDUPILOT_SITL`, else
      `../shared/sitl/arducopter` beside the project)
    * `--sitl-defaults FILE` — its parameter defaults (else `copter.parm` beside
      the binary); repeatable, later files win
    * `--fake N` — N fake vehicles of the fake platform
      (`Dolphin.Fleet.FakeSource`, no MAVLink): to try a script's logic with
      `Dolphin.Engine.FakePlatform` tasks
    * `--fleet FILE` — a fleet file (`Dolphin.Check.FleetFile`, the JSON file
      `mix dolphin.check --fleet` reads): each vehicle it lists carries its
      `payloads` (those MAVLink cannot announce: `"sidescan"`, `"smoke"`), by
      system id, for `pick(payload: ...)` (a vehicle needs no `position`
      there: it reports its own); the pre-flight check of `--sim` and
      `--sitl` counts them too
    * `--sim copter:2+smoke` — simulated vehicles whose companion
      computer carries sensors (`smoke`, `water_temp`, `range`:
      `Dolphin.Sim.Companion`), publishing NAMED_VALUE_FLOAT readings
    * `--world FILE` — what simulated sensors sense (`Dolphin.Sim.World`:
      fires and their smoke drifting with the wind, water temperature,
      obstacles), with `--sim`; a file with a mistyped or missing key, a
      value out of range or bad JSON is refused with the key and its line
    * `--home LAT,LON[,ALT]` — where `--sim` and `--sitl` vehicles start
      (around that point, 30 m apart; default the report's, in Serra da
      Estrela; a submarine starts at the surface)
    * `--seed N` — the simulator's seed
    * `--speedup K` — run K times faster than real time (`Dolphin.Clock`),
      from 0.01 to 1000 (beyond, the simulated vehicles cannot keep up)
    * `--for DURATION` — stop the script after that much clock time (`90s`,
      `10m`, `1h`, `500ms`; a bare number is seconds; more than 0, and at
      most 49.7 days of real time): running tasks are
      stopped, vehicles hold, exit status 0 with a summary
    * `--events FILE` — write every event as a JSON line (schema: `Dolphin.Events`)
    * `--tlog FILE` — where to record every MAVLink frame of the links (a
      telemetry log); a FILE that is there is replaced (said when the run
      starts): a log holds one run. By default a run that talks MAVLink
      writes one to `logs/DATE_TIME-SCRIPT.tlog`
    * `--no-tlog` — no telemetry log
    * `--forward ENDPOINT` — copy all traffic to a `udpout` endpoint (QGroundControl); repeatable
    * `--quiet` — print only the script's messages, errors and the summary
    * `--report FILE` — when the run has ended, write its flight report
      (`Dolphin.Report`: HTML, from the run's telemetry log and its
      `--events` file when given) to FILE, and say where; not with
      `--no-tlog` or `--fake` (no telemetry log to make it from)
    * `--web PORT` — serve a live view of the run (`Dolphin.Web`: the flight
      report's page, updated as the vehicles fly) on `http://127.0.0.1:PORT/`
      while it goes on (0: a free port, printed); read-only
    * `--web-bind ADDRESS` — listen on ADDRESS instead of 127.0.0.1
      (`0.0.0.0`: from other machines too)
    * `--no-check` — fly without the pre-flight check (`mix dolphin.check`)
    * `--sname NAME`, `--name NAME@HOST` — make this a node of a cluster of
      ground stations (`Dolphin.Cluster`; short or long names, as `erl`)
    * `--cookie C` — the cluster's cookie (else `~/.erlang.cookie`)
    * `--join NODE` — fly the vehicles of the ground station `NODE`
      (`mix dolphin.station`) too, as one fleet; repeatable. Without
      `--speedup` the run adopts the stations' speed-up; with another one it
      refuses (exit 1). Unreachable or refusing nodes end the run (exit 1).

  ## Several ground stations

      mix dolphin.station --sname gs1 --sim 2 --speedup 10            # terminal 1
      mix dolphin.station --sname gs2 --sim 2 --first-sysid 11 --speedup 10   # terminal 2
      mix dolphin.run examples/two_vehicles.exs --sname ctl --join gs1@$(hostname -s) --join gs2@$(hostname -s)

  See `docs/cluster.md`.

  ## Output

  On a terminal, the events scroll above a status block redrawn twice a
  second: one line per vehicle with its mode, armed state, battery bar,
  height, mission progress and the task it flies (`Dolphin.CLI.StatusBlock`).
  Elsewhere (a pipe, a file, CI) the events are plain timestamped lines.
  Their times, like the summary's (`script stopped after 1808.2 s of clock
  time`), are clock time since the run started, its vehicles' start
  included; `--for` counts from the script's start, which the summary gives.
  The lines are `Dolphin.EventText`'s, as in the console; the run itself is
  `Dolphin.CLI.Run`.

  ## Watching a run in QGroundControl

  QGroundControl listens on UDP 14550; give Dolphin another port and forward
  to QGroundControl's:

      mix dolphin.run examples/two_vehicles.exs --sim 2 --speedup 5 --forward udpout:127.0.0.1:14550

  QGroundControl then sees every vehicle (and Dolphin's own heartbeat, system
  255) and shows them on its map while the script flies them; keep the
  speed-up low so that its displays keep up.

  With none of `--connect`, `--sim`, `--fake`, the links of the configuration
  are used (`config :dolphin, links: [...]`), or if there are none the ground
  station listens on `Dolphin.Link.default_endpoint/0` (`udpin:0.0.0.0:14550`).

  ## Watching a run in the browser

      mix dolphin.run examples/two_vehicles.exs --sim 2 --speedup 5 --web 8080 --report run.html

  prints `live view: http://127.0.0.1:8080/`: the flight report's page
  (`Dolphin.Report`), kept up to date while the script runs (`Dolphin.Web`:
  vehicles moving on the map, task bars growing, what each vehicle does
  now). When the run ends, `--report` writes the report of the whole run
  and prints where.

  ## Interrupting a run

  Ctrl-C (SIGINT) or SIGTERM stops the script the way `--for` does: running
  tasks are stopped (each says why), vehicles are told to hold, the summary
  is printed and the script's events end with `script_finished` (result
  `stopped`); the vehicles' own events may follow it until the run ends (a
  vehicle's `mode_changed` as its heartbeat shows the hold it accepted).
  The same signal again within a second is taken as a repeat (a key pressed
  twice, `timeout` signalling the run and its process group); once the log
  says `still stopping`, another exits at once, without waiting for the
  stops: the log and the `--events` file keep what they had, and a line
  says so. Before the run starts (the script compiled, the pre-flight
  check) a signal ends the command at once, saying so. (Ctrl-C is caught
  by `c_src/dolphin_signals.c`, built into `priv/` with the project;
  without a C compiler it opens the Erlang BREAK menu, as it does while
  `mix` itself starts. Under IEx both keep their usual meaning.)

  ## Exit status

  As every task's (README.md, "Exit status"): 0 — the script completed (or
  `--for` ended it); 1 — the script failed (could not compile, the
  pre-flight check found errors, a task failed, `halt`, a pick timed out:
  the message says what, where and why) or its vehicles could not be
  started (a port in use, a SITL binary missing, the `--web` port in use);
  2 — bad usage (an unknown option, a value out of range, a bad endpoint,
  no such script, a directory given for a file, an output file — `--tlog`,
  `--events`, `--report` — that cannot be written: the message names the
  flag, the value and what is allowed); 130 — Ctrl-C (SIGINT) stopped it;
  143 — SIGTERM stopped it (128 + the signal's number, as a shell says), at
  any moment from the task's start; 141 — its standard output was closed
  (`| head`): it ended at once, quietly, as a closed pipe ends a command
  (`Dolphin.CLI.Stdout`).
  """

  use Mix.Task

  alias Dolphin.CLI.{Run, Signals, Values}

  @options Values.fleet_options() ++
             [
               fake: :vehicles,
               for: :string,
               events: :output,
               no_tlog: :boolean,
               quiet: :boolean,
               report: :output,
               web: :port,
               web_bind: :string,
               no_check: :boolean
             ] ++ Dolphin.CLI.Cluster.switches()

  @usage "usage: mix dolphin.run SCRIPT [--connect ENDPOINT]... [--sim N | --sitl N|AIRFRAME:N,... | --fake N] [--fleet FILE] [--world FILE] [--home LAT,LON] [--speedup K] [--for DURATION] [--events FILE] [--tlog FILE | --no-tlog] [--forward ENDPOINT]... [--quiet] [--report FILE] [--web PORT [--web-bind ADDRESS]] [--no-check] [--sname NAME | --name NAME@HOST] [--cookie C] [--join NODE]..."

  @impl Mix.Task
  def run(argv) do
    if iex?() do
      # `iex -S mix dolphin.run ...`: the script runs in the background and the
      # console stays usable (`import Dolphin.Console`: vehicles(), tasks(),
      # stop/1, answer/1 for the script's `ask`). Plain log lines: a status
      # block redrawn in place would fight the prompt.
      # The application is up before the prompt comes, so that the console's helpers work at once.
      Mix.Task.run("app.start")
      {:ok, _} = Task.Supervisor.start_child(Dolphin.Console.Commands, fn -> main(argv, plain: true, ask: &Dolphin.Console.Runs.ask/1) end)
      :ok
    else
      # Until the run catches them (while it runs, they stop the script: see
      # "Interrupting a run"), Ctrl-C and SIGTERM end the command at once.
      Signals.exit_on_signal("dolphin.run", "no script was running; exiting")
      # A closed pipe (`| head`) ends the run at once, quietly (status 141).
      Dolphin.CLI.Stdout.watch()

      case parse(argv) do
        {:ok, file, opts} ->
          case execute(file, opts, signals: true) do
            0 -> :ok
            code -> exit({:shutdown, code})
          end

        {:error, e} ->
          Mix.raise(usage(e), exit_status: 2)
      end
    end
  end

  defp iex?, do: Code.ensure_loaded?(IEx) and IEx.started?()

  @doc """
  Does the work of the task and returns the exit status. `io` options:
  `:out` and `:err` (devices, default `:stdio` and `:stderr`), `:plain`
  (never the status block), `:ask` (the script's `ask/1`), `:signals`
  (SIGINT and SIGTERM stop the script, `Dolphin.CLI.Signals`) and `:sitl`
  (more options of `Dolphin.SITL.start/2` for `--sitl`, such as `:send_to`).
  """
  @spec main([String.t()], keyword()) :: 0 | 1 | 2 | 130 | 143
  def main(argv, io \\ []) do
    case parse(argv) do
      {:ok, file, opts} ->
        execute(file, opts, io)

      {:error, e} ->
        IO.puts(Keyword.get(io, :err, :stderr), usage(e))
        2
    end
  end

  defp usage(%Dolphin.CommandLineError{reason: :usage} = e), do: "mix dolphin.run: #{Exception.message(e)}\n#{@usage}"

  # Compiles the script, then runs it (Dolphin.CLI.Run); the exit status.
  defp execute(file, opts, io) do
    err = Keyword.get(io, :err, :stderr)
    Mix.Task.run("app.config")

    case Dolphin.Script.compile(file) do
      {:ok, script} ->
        try do
          Mix.Task.run("app.start")
          run_opts = opts ++ Keyword.take(io, [:out, :err, :plain, :ask, :signals]) ++ [sitl_extra: Keyword.get(io, :sitl, [])]

          # Nothing is started when the pre-flight check refuses.
          case Run.check(script, opts, Keyword.get(io, :out, :stdio)) == :ok and Run.run(script, run_opts) do
            false ->
              1

            :completed ->
              0

            :stopped ->
              0

            {:stopped, signal} ->
              Signals.status(signal)

            :failed ->
              1

            # The usage was right (endpoints are checked when parsed): a port in
            # use, a SITL binary that would not start... the run failed.
            {:error, e} ->
              IO.puts(err, "mix dolphin.run: #{Exception.message(e)}")
              1
          end
        after
          Dolphin.Script.purge(script)
        end

      {:error, e} ->
        IO.puts(err, Dolphin.Script.Error.format(e))
        1
    end
  end

  @doc false
  # The script and the options of a command line, checked (the endpoints
  # parse, the script is a file), with the duration of --for as :for_ms.
  @spec parse([String.t()]) :: {:ok, Path.t(), keyword()} | {:error, Dolphin.CommandLineError.t()}
  def parse(argv) do
    Values.parse_script(argv, Values.switches(@options), fn file, opts ->
      with {:ok, opts} <- Values.check(opts, @options),
           :ok <- exclusive(opts),
           :ok <- web(opts),
           :ok <- report(opts),
           :ok <- Values.world(opts),
           :ok <- cluster(opts),
           {:ok, for_ms} <- duration(opts[:for]),
           :ok <- within_a_timer(for_ms, opts),
           :ok <- Values.input_file(file, "script") do
        {:ok, file, Keyword.put(opts, :for_ms, for_ms)}
      end
    end)
  end

  defp usage_error(message), do: Dolphin.CommandLineError.usage_error(message)

  # The script's deadline is one timer: it holds 49.7 days of real time.
  defp within_a_timer(nil, _opts), do: :ok

  defp within_a_timer(for_ms, opts) do
    k = opts[:speedup] || 1
    max_ms = Dolphin.Clock.max_wait_ms(k)

    if for_ms <= max_ms,
      do: :ok,
      else: usage_error("--for #{opts[:for]}: at most #{div(max_ms, 3_600_000)} h at speed-up #{Dolphin.Console.Format.num(k / 1)} (49.7 days of real time, the longest a timer holds)")
  end

  defp exclusive(opts) do
    case Enum.filter([:sim, :sitl, :fake], &opts[&1]) do
      [_, _ | _] = given -> usage_error(Enum.map_join(given, " and ", &"--#{&1}") <> " do not go together")
      _ -> :ok
    end
  end

  defp web(opts) do
    cond do
      opts[:web_bind] && !opts[:web] -> usage_error("--web-bind goes with --web PORT")
      opts[:web_bind] && match?({:error, _}, :inet.parse_strict_address(String.to_charlist(opts[:web_bind]))) -> usage_error("--web-bind takes an IP address, got #{inspect(opts[:web_bind])}")
      true -> :ok
    end
  end

  defp report(opts) do
    cond do
      !opts[:report] -> :ok
      opts[:no_tlog] -> usage_error("--report is made from the run's telemetry log: not with --no-tlog")
      opts[:fake] -> usage_error("--report is made from the run's telemetry log, and fake vehicles write none: not with --fake")
      true -> :ok
    end
  end

  defp cluster(opts) do
    case Dolphin.CLI.Cluster.check(opts) do
      :ok -> :ok
      {:error, message} -> usage_error(message)
    end
  end

  @doc """
  A duration in clock milliseconds, more than 0: `500ms`, `90s`, `10m`, `1h`, `1.5h`; a bare number is seconds.

      iex> Mix.Tasks.Dolphin.Run.duration("10m")
      {:ok, 600000}
      iex> Mix.Tasks.Dolphin.Run.duration("2.5")
      {:ok, 2500}
      iex> {:error, %Dolphin.CommandLineError{reason: :usage, message: message}} = Mix.Tasks.Dolphin.Run.duration("soon")
      iex> message
      "--for soon: a duration more than 0 such as 90s, 10m, 1h or 500ms (a bare number is seconds)"
  """
  @spec duration(String.t() | nil) :: {:ok, pos_integer() | nil} | {:error, Dolphin.CommandLineError.t()}
  def duration(nil), do: {:ok, nil}

  def duration(text) do
    with {:ok, [for: ms]} <- Values.check([for: text], for: :duration), do: {:ok, ms}
  end
end
