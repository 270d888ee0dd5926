defmodule Mix.Tasks.Dolphin.Run do
  @shortdoc "Runs a Dolphin script against real, simulated or fake vehicles"

  @moduledoc """
  Runs a Dolphin script (see `Dolphin.Script`).

      mix dolphin.run examples/single_vehicle.exs --sim 1 --speedup 50
      mix dolphin.run survey.exs --connect udpin:0.0.0.0:14550 --events run.jsonl --tlog run.tlog
      mix dolphin.run logic.exs --fake 3 --for 10m

  The script is read and compiled first: a syntax error or an unknown word is
  reported with file and line before anything is sent to a vehicle.

  Under IEx (`iex -S mix dolphin.run SCRIPT ...`) the script runs in the
  background and the console stays usable: `Dolphin.Console`'s `vehicles()`,
  `tasks()`, `stop/1`, and `answer/1` for the script's `ask`.

  ## Options

    * `--connect ENDPOINT` — a link to vehicles (`udpin:0.0.0.0:14550`,
      `udpout:HOST:PORT`, `tcp:HOST:PORT`); repeatable
    * `--sim N` — start N simulated vehicles (`Dolphin.Sim`: ArduCopters with a
      camera) on a local link
    * `--sitl N` — start N ArduCopter SITL instances (`Dolphin.SITL`: ArduPilot's
      own flight code) on a local link, at the run's speed-up
    * `--sitl-bin PATH` — the SITL binary (else `$ARDUPILOT_SITL`, else
      `../shared/sitl/arducopter` beside the project)
    * `--sitl-defaults FILE` — its parameter defaults (else `copter.parm` beside
      the binary); repeatable, later files win
    * `--fake N` — N fake vehicles of the test platform
      (`Dolphin.Fleet.TestSource`, no MAVLink): to try a script's logic with
      `Dolphin.Engine.TestPlatform` tasks
    * `--seed N` — the simulator's seed
    * `--speedup K` — run K times faster than real time (`Dolphin.Clock`)
    * `--for DURATION` — stop the script after that much clock time (`90s`,
      `10m`, `1h`, `500ms`; a bare number is seconds): running tasks are
      stopped, vehicles hold, exit status 0 with a summary
    * `--events FILE` — write every event as a JSON line (schema: `Dolphin.Telemetry`)
    * `--tlog FILE` — where to record every MAVLink frame of the links (a
      telemetry log); by default a run that talks MAVLink writes one to
      `logs/DATE_TIME-SCRIPT.tlog`
    * `--no-tlog` — no telemetry log
    * `--forward ENDPOINT` — copy all traffic to a `udpout` endpoint (QGroundControl); repeatable
    * `--quiet` — print only the script's messages, errors and the summary

  ## Output

  On a terminal, the events scroll above a status block redrawn twice a
  second: one line per vehicle with its mode, armed state, battery bar,
  height, mission progress and the task it flies (`Dolphin.Run.StatusBlock`).
  Elsewhere (a pipe, a file, CI) the events are plain timestamped lines.

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

  ## Interrupting a run

  Ctrl-C (SIGINT) or SIGTERM stops the script the way `--for` does: running
  tasks are stopped (each says why), vehicles are told to hold, the summary
  is printed and the events end with `script_finished` (result `stopped`).
  A second Ctrl-C or SIGTERM exits at once, without waiting for the stops.
  (Ctrl-C is caught by `c_src/dolphin_signals.c`, built into `priv/` with
  the project; without a C compiler it opens the Erlang BREAK menu. Under
  IEx both keep their usual meaning.)

  ## Exit status

  0 — the script completed (or `--for` ended it); 1 — the script failed
  (could not compile, a task failed, `halt`, a pick timed out: the message
  says what, where and why) or its vehicles could not be started (a port in
  use, a SITL binary missing); 2 — bad usage (an unknown option, a bad
  endpoint, no such script); 130 — Ctrl-C (SIGINT) stopped
  it; 143 — SIGTERM stopped it (128 + the signal's number, as a shell says).
  """

  use Mix.Task

  alias Dolphin.Fleet.TestSource
  alias Dolphin.Run.StatusBlock

  # How often the status block is redrawn on a terminal (real time).
  @redraw_ms 500

  @switches [
    connect: :keep,
    sim: :integer,
    sitl: :integer,
    sitl_bin: :string,
    sitl_defaults: :keep,
    fake: :integer,
    seed: :integer,
    speedup: :float,
    for: :string,
    events: :string,
    tlog: :string,
    no_tlog: :boolean,
    forward: :keep,
    quiet: :boolean
  ]

  @usage "usage: mix dolphin.run SCRIPT [--connect ENDPOINT]... [--sim N | --sitl N | --fake N] [--speedup K] [--for DURATION] [--events FILE] [--tlog FILE | --no-tlog] [--forward ENDPOINT]... [--quiet]"

  @impl Mix.Task
  def run(argv) do
    if iex?() do
      # `iex -S mix dolphin.run ...`: the script runs in the background and the
      # console stays usable (`import Dolphin.Console`: vehicles(), tasks(),
      # stop/1, answer/1 for the script's `ask`). Plain log lines: a status
      # block redrawn in place would fight the prompt.
      # The application is up before the prompt comes, so that the console's helpers work at once.
      Mix.Task.run("app.start")
      {:ok, _} = Task.start(fn -> main(argv, plain: true, ask: &Dolphin.Console.Runs.ask/1) end)
      :ok
    else
      # Ctrl-C and SIGTERM stop the script (see "Exit status"), not the VM.
      case main(argv, signals: true) do
        0 -> :ok
        code -> exit({:shutdown, code})
      end
    end
  end

  defp iex?, do: Code.ensure_loaded?(IEx) and IEx.started?()

  @doc """
  Does the work of the task and returns the exit status. `io` options:
  `:out` and `:err` (devices, default `:stdio` and `:stderr`), `:plain`
  (never the status block), `:ask` (the script's `ask/1`), `:signals`
  (SIGINT and SIGTERM stop the script, `Dolphin.Run.Signals`) and `:sitl`
  (more options of `Dolphin.SITL.start/2` for `--sitl`, such as `:send_to`).
  """
  @spec main([String.t()], keyword()) :: 0 | 1 | 2 | 130 | 143
  def main(argv, io \\ []) do
    out = Keyword.get(io, :out, :stdio)
    err = Keyword.get(io, :err, :stderr)

    case parse(argv) do
      {:ok, file, opts} ->
        Mix.Task.run("app.config")

        case Dolphin.Script.compile(file) do
          {:ok, script} ->
            try do
              Mix.Task.run("app.start")
              run_script(script, opts ++ Keyword.take(io, [:plain, :ask, :signals]) ++ [sitl_extra: Keyword.get(io, :sitl, [])], out, err)
            after
              Dolphin.Script.purge(script)
            end

          {:error, e} ->
            IO.puts(err, Dolphin.Script.Error.format(e))
            1
        end

      {:error, message} ->
        IO.puts(err, "mix dolphin.run: #{message}\n#{@usage}")
        2
    end
  end

  @doc false
  # {:ok, script, opts} | {:error, message}
  def parse(argv) do
    case OptionParser.parse(argv, strict: @switches) do
      {opts, [file], []} ->
        with :ok <- positive(opts, :sim),
             :ok <- positive(opts, :sitl),
             :ok <- positive(opts, :fake),
             :ok <- exclusive(opts),
             :ok <- speedup(opts[:speedup]),
             :ok <- endpoints(opts),
             {:ok, for_ms} <- duration(opts[:for]),
             :ok <- readable(file) do
          {:ok, file, Keyword.put(opts, :for_ms, for_ms)}
        end

      {_, [], []} ->
        {:error, "no script given"}

      {_, [_, extra | _], []} ->
        {:error, "one script at a time (unexpected #{inspect(extra)})"}

      {_, _, [{switch, value} | _]} ->
        {:error, "bad option #{switch}#{if value, do: " " <> value, else: ""}"}
    end
  end

  defp positive(opts, key) do
    case opts[key] do
      nil -> :ok
      n when n > 0 -> :ok
      n -> {:error, "--#{key} must be a positive number of vehicles, got #{n}"}
    end
  end

  defp exclusive(opts) do
    case Enum.filter([:sim, :sitl, :fake], &opts[&1]) do
      [_, _ | _] = given -> {:error, Enum.map_join(given, " and ", &"--#{&1}") <> " do not go together"}
      _ -> :ok
    end
  end

  defp endpoints(opts) do
    given = for {key, ep} <- opts, key in [:connect, :forward], do: {key, ep}

    Enum.reduce_while(given, :ok, fn {key, ep}, :ok ->
      case Dolphin.Link.Endpoint.parse(ep) do
        {:ok, _} -> {:cont, :ok}
        {:error, e} -> {:halt, {:error, "--#{key} #{ep}: #{Exception.message(e)}"}}
      end
    end)
  end

  defp speedup(nil), do: :ok
  defp speedup(k) when k > 0, do: :ok
  defp speedup(k), do: {:error, "--speedup must be positive, got #{k}"}

  defp readable(file) do
    if File.regular?(file), do: :ok, else: {:error, "no such script: #{file}"}
  end

  @doc """
  A duration in clock milliseconds: `500ms`, `90s`, `10m`, `1h`, `1.5h`; a bare number is seconds.

      iex> Mix.Tasks.Dolphin.Run.duration("10m")
      {:ok, 600000}
      iex> Mix.Tasks.Dolphin.Run.duration("2.5")
      {:ok, 2500}
  """
  @spec duration(String.t() | nil) :: {:ok, non_neg_integer() | nil} | {:error, String.t()}
  def duration(nil), do: {:ok, nil}

  def duration(text) do
    case Float.parse(text) do
      {n, unit} when n >= 0 and unit in ["", "s", "ms", "m", "min", "h"] ->
        {:ok, round(n * %{"" => 1000, "s" => 1000, "ms" => 1, "m" => 60_000, "min" => 60_000, "h" => 3_600_000}[unit])}

      _ ->
        {:error, "--for takes a duration such as 90s, 10m, 1h or 500ms, got #{inspect(text)}"}
    end
  end

  # --- running ---

  defp run_script(script, opts, out, err) do
    previous_speedup = Dolphin.Clock.speedup()
    if k = opts[:speedup], do: Dolphin.Clock.set_speedup(k)
    origin = Dolphin.Clock.now_ms()
    Process.put(:dolphin_run_cleanup, [])
    catch_signals(opts)

    try do
      opts = Keyword.put(opts, :tlog, tlog_path(opts, script.file))
      start_outputs(opts, origin, out)
      if opts[:tlog] && !opts[:quiet], do: IO.puts(out, "telemetry log: #{opts[:tlog]}")

      case start_vehicles(opts, out) do
        :ok ->
          {result, signal} = run_until_signal(script, opts)
          # The log and the status block end before the summary is printed below them.
          stop_outputs()
          report(result, Keyword.put(opts, :signal, signal), out, err)

        # The usage was right (endpoints are checked when parsed): a port in
        # use, a SITL binary that would not start... the run failed.
        {:error, message} ->
          IO.puts(err, "mix dolphin.run: #{message}")
          1
      end
    after
      # The outputs stop first (they show the run, not its teardown); then
      # the last started is the first stopped: the simulator before its link.
      stop_outputs()
      Enum.each(Process.delete(:dolphin_run_cleanup), fn {_, fun} -> fun.() end)
      Dolphin.Clock.set_speedup(previous_speedup)
    end
  end

  # The script's result and the signal that stopped it (nil: none did).
  defp run_until_signal(script, opts) do
    {:ok, pid} = Dolphin.Script.start(script, [for: opts[:for_ms]] ++ Keyword.take(opts, [:ask]))
    if opts[:signals], do: await_script(pid, nil), else: {Dolphin.Script.await(pid), nil}
  end

  defp await_script(pid, signal) do
    receive do
      {Dolphin.Script, ^pid, result} ->
        {result, signal}

      {:dolphin_signal, sig} when signal == nil ->
        Dolphin.Script.stop(pid, {:signal, sig})
        # In the log, so that the status block stays whole below it.
        send(Process.get(:dolphin_run_printer), {:note, "#{signal_name(sig)}: stopping the script (tasks stop, vehicles hold); again to exit at once"})
        await_script(pid, sig)
    end
  end

  # From the start of the run to its end (teardown included), a first SIGINT
  # or SIGTERM comes to this process as a message: the script stops as with
  # `--for` (at once if it comes before the script starts). A second one ends
  # the run at once, with the status of that signal.
  defp catch_signals(opts) do
    if opts[:signals] do
      owner = self()

      relay =
        spawn_link(fn ->
          receive do: ({:dolphin_signal, _} = first -> send(owner, first))
          receive do: ({:dolphin_signal, sig} -> System.halt(signal_status(sig)))
        end)

      Dolphin.Run.Signals.catch_signals(relay)
      defer(
        fn ->
          Dolphin.Run.Signals.release_signals()
          Process.unlink(relay)
          Process.exit(relay, :kill)
        end,
        :signals
      )
    end
  end

  defp signal_name(:sigint), do: "interrupted (SIGINT, Ctrl-C)"
  defp signal_name(:sigterm), do: "terminated (SIGTERM)"

  defp signal_status(:sigint), do: 130
  defp signal_status(:sigterm), do: 143

  # Every run that talks MAVLink keeps a telemetry log unless told not to:
  # logs/<date>-<time>-<script>.tlog, readable by pymavlink, MAVExplorer and
  # `mix mavlink.decode --tlog`.
  defp tlog_path(opts, file) do
    cond do
      opts[:no_tlog] || opts[:fake] ->
        nil

      path = opts[:tlog] ->
        path

      true ->
        {{y, mo, d}, {h, mi, sec}} = :calendar.local_time()
        stamp = :io_lib.format("~4..0B-~2..0B-~2..0B_~2..0B-~2..0B-~2..0B", [y, mo, d, h, mi, sec]) |> IO.iodata_to_binary()
        File.mkdir_p!("logs")
        base = Path.join("logs", "#{stamp}-#{Path.basename(file, ".exs")}")
        # Two runs of one script in the same second get two logs.
        Enum.find(Stream.map(Stream.iterate(1, &(&1 + 1)), &"#{base}#{if &1 > 1, do: "-#{&1}"}.tlog"), &(not File.exists?(&1)))
    end
  end

  defp stop_outputs do
    {outputs, others} = Enum.split_with(Process.get(:dolphin_run_cleanup), &match?({:output, _}, &1))
    Process.put(:dolphin_run_cleanup, others)
    Enum.each(outputs, fn {_, fun} -> fun.() end)
  end

  # Something to undo when the run ends.
  defp defer(fun, kind \\ :vehicles), do: Process.put(:dolphin_run_cleanup, [{kind, fun} | Process.get(:dolphin_run_cleanup)])

  defp start_outputs(opts, origin, out) do
    parent = self()

    # On a terminal the log scrolls above a status block redrawn in place;
    # elsewhere (pipes, CI, files) it is plain timestamped lines.
    tty = if !opts[:quiet] && !opts[:plain], do: terminal(out)
    live = tty != nil

    printer =
      spawn_link(fn ->
        Dolphin.Telemetry.subscribe()
        send(parent, {:printer_ready, self()})
        if live, do: Process.send_after(self(), :redraw, @redraw_ms)
        print_loop(%{out: out, origin: origin, quiet: opts[:quiet], live: live, block: 0, tasks: %{}, columns: if(live, do: columns(tty), else: 80)})
      end)

    receive do: ({:printer_ready, ^printer} -> :ok)
    Process.put(:dolphin_run_printer, printer)
    defer(fn -> stop_printer(Process.delete(:dolphin_run_printer)) end, :output)

    if path = opts[:events] do
      case Dolphin.Telemetry.Writer.start_link(path: path, origin_ms: origin) do
        {:ok, w} -> defer(fn -> Dolphin.Telemetry.Writer.stop(w) end, :output)
        {:error, why} -> raise Mix.Error, message: "--events: #{why}"
      end
    end
  end

  # The printer prints what it was sent before it was told to stop.
  defp stop_printer(printer) do
    ref = Process.monitor(printer)
    send(printer, :stop)

    receive do
      {:DOWN, ^ref, _, _, _} -> :ok
    after
      2_000 -> Process.exit(printer, :kill)
    end
  end

  defp start_vehicles(opts, out) do
    link_opts = Enum.reject([tlog: opts[:tlog], forward: Keyword.get_values(opts, :forward)], fn {_, v} -> v in [nil, []] end)

    with :ok <- connect_all(Keyword.get_values(opts, :connect), link_opts) do
      cond do
        n = opts[:sim] -> start_sim(n, opts, link_opts, out)
        n = opts[:sitl] -> start_sitl(n, opts, link_opts, out)
        n = opts[:fake] -> start_fake(n, out)
        opts[:connect] != nil or Application.get_env(:dolphin, :links, []) != [] -> :ok
        true -> listen_default(link_opts, out)
      end
    end
  end

  # Told nothing: listen where vehicles and simulators send by default.
  defp listen_default(link_opts, out) do
    endpoint = Dolphin.Link.default_endpoint()

    with :ok <- connect_all([endpoint], link_opts) do
      IO.puts(out, "listening on #{endpoint} (no --connect, --sim or --fake given)")
    end
  end

  defp connect_all(endpoints, link_opts) do
    Enum.reduce_while(endpoints, :ok, fn ep, :ok ->
      case Dolphin.Link.connect(ep, link_opts) do
        {:ok, pid} ->
          defer(fn -> DynamicSupervisor.terminate_child(Dolphin.Link.Supervisor, pid) end)
          {:cont, :ok}

        {:error, e} ->
          {:halt, {:error, "--connect #{ep}: #{Exception.message(e)}"}}
      end
    end)
  end

  defp start_sim(n, opts, link_opts, out) do
    case Dolphin.Sim.Local.start(n, [seed: Keyword.get(opts, :seed, 1)] ++ link_opts) do
      {:ok, sim} ->
        defer(fn -> Dolphin.Sim.Local.stop(sim) end)
        IO.puts(out, "#{n} simulated vehicle(s) #{Dolphin.Fleet.VehicleSet.format(sim.sysids)} on 127.0.0.1:#{sim.port}")
        :ok

      error ->
        error
    end
  end

  defp start_sitl(n, opts, link_opts, out) do
    sitl_opts = [bin: opts[:sitl_bin], defaults: Keyword.get_values(opts, :sitl_defaults)] ++ link_opts ++ Keyword.get(opts, :sitl_extra, [])

    case Dolphin.SITL.start(n, Enum.reject(sitl_opts, fn {_, v} -> v in [nil, []] end)) do
      {:ok, fleet} ->
        defer(fn -> Dolphin.SITL.stop(fleet) end)
        IO.puts(out, "#{n} ArduCopter SITL instance(s), vehicles #{Enum.join(fleet.sysids, ", ")}, on 127.0.0.1:#{fleet.port} at #{Dolphin.Clock.speedup()}x")
        :ok

      {:error, e} ->
        {:error, Exception.message(e)}
    end
  end

  defp start_fake(n, out) do
    name = :"dolphin_run_fakes_#{System.unique_integer([:positive])}"
    {:ok, source} = TestSource.start_link(name: name)
    Process.unlink(source)
    defer(fn -> GenServer.stop(source) end)
    previous = Dolphin.Fleet.source()
    :ok = Dolphin.Fleet.set_source(TestSource.source(name))
    defer(fn -> Dolphin.Fleet.set_source(previous) end)
    for id <- 1..n, do: TestSource.add(name, id, type: :uav)
    IO.puts(out, "#{n} fake vehicle(s) [1..#{n}] of the test platform (no MAVLink: missions cannot fly on them)")
    :ok
  end

  defp report({:ok, %{result: :done, duration_ms: ms}}, _opts, out, _err) do
    IO.puts(out, "script completed in #{seconds(ms)} of clock time")
    0
  end

  defp report({:ok, %{result: :stopped, duration_ms: ms}}, opts, out, _err) do
    why =
      case opts[:signal] do
        nil -> if opts[:for_ms], do: "--for #{opts[:for]} is over", else: "stopped"
        sig -> signal_name(sig)
      end

    IO.puts(out, "script stopped after #{seconds(ms)} of clock time (#{why}): running tasks were stopped, vehicles hold")
    if sig = opts[:signal], do: signal_status(sig), else: 0
  end

  defp report({:error, %Dolphin.Script.Error{} = e}, _opts, _out, err) do
    IO.puts(err, Dolphin.Script.Error.format(e))
    1
  end

  defp seconds(ms), do: :erlang.float_to_binary(ms / 1000, decimals: 1) <> " s"

  # --- live output: one line per event worth an operator's eye ---

  # The terminal our standard output is, if it is one (a device under /dev/pts
  # or /dev/tty that is not "dumb"), or nil. (`mix` runs without a shell, where
  # OTP 25 cannot ask the terminal itself: what our output is connected to tells.)
  defp terminal(:stdio) do
    case File.read_link("/proc/self/fd/1") do
      {:ok, "/dev/" <> kind = device} ->
        if (String.starts_with?(kind, "pts/") or String.starts_with?(kind, "tty")) and System.get_env("TERM") not in [nil, "", "dumb"], do: device

      _ ->
        nil
    end
  end

  defp terminal(_device), do: nil

  # Its width: `mix` has no shell to ask, and the BEAM's child processes no
  # controlling terminal, so the device itself is asked.
  defp columns(device) do
    with [_rows, cols] <- :os.cmd(String.to_charlist("stty size < #{device} 2>/dev/null")) |> to_string() |> String.split(),
         {n, ""} when n > 20 <- Integer.parse(cols) do
      n
    else
      _ -> 80
    end
  end

  defp print_loop(p) do
    receive do
      :ready ->
        print_loop(p)

      :redraw ->
        Process.send_after(self(), :redraw, @redraw_ms)
        print_loop(draw_block(p))

      :stop ->
        drain(p)

      {:dolphin, :events, event} ->
        print_loop(print(track(p, event), event))

      {:note, text} ->
        print_loop(print_line(p, Dolphin.Clock.now_ms(), text))
    end
  end

  defp drain(p) do
    receive do
      {:dolphin, :events, event} -> drain(print(track(p, event), event))
    after
      0 -> p
    end
  end

  defp print(p, event) do
    case line(event, p.quiet) do
      nil -> p
      text -> print_line(p, event.at_ms, text)
    end
  end

  defp print_line(p, at_ms, text) do
    log = "[#{String.pad_leading(seconds(at_ms - p.origin), 9)}] #{text}\n"
    # The block is erased, the line written where it was, and the block drawn again below.
    if p.live, do: draw_block(%{p | block: 0}, [StatusBlock.erase(p.block), log]), else: IO.write(p.out, log) && p
  end

  # Which task each vehicle flies, for the status block.
  defp track(p, %{event: :task_started, vehicle: v, task_id: id, name: name}) when v != nil, do: put_in(p.tasks[v], {id, name})

  defp track(p, %{event: :task_finished, vehicle: v, task_id: id}) when v != nil do
    case p.tasks do
      %{^v => {^id, _}} -> %{p | tasks: Map.delete(p.tasks, v)}
      _ -> p
    end
  end

  defp track(p, _event), do: p

  defp draw_block(p, before \\ []) do
    # A fleet busy or restarting leaves the block empty for a moment, not the run broken.
    vehicles =
      try do
        for %{vehicle: v} <- Dolphin.Fleet.vehicles(), do: v
      catch
        :exit, _ -> []
      end

    tasks = Map.new(p.tasks, fn {v, {_id, name}} -> {v, name} end)
    # A line wider than the terminal would wrap, and the block's redraw would miss its rows.
    lines = StatusBlock.render(vehicles, tasks, Dolphin.Clock.now_ms() - p.origin) |> Enum.map(&String.slice(&1, 0, p.columns - 1))
    IO.write(p.out, [before, StatusBlock.redraw(p.block, lines)])
    %{p | block: length(lines)}
  end

  @doc false
  # One event as a log line (nil: not shown); public for the tests of how ids print.
  def line(event, quiet)
  def line(%{event: :message, text: text}, _quiet), do: "message: #{text}"
  def line(_event, true), do: nil
  def line(%{event: :vehicle_discovered} = e, _), do: "vehicle #{e.vehicle} discovered (#{e.type})"
  def line(%{event: :vehicle_lost} = e, _), do: "vehicle #{e.vehicle} lost"
  def line(%{event: :vehicle_reconnected} = e, _), do: "vehicle #{e.vehicle} reconnected"
  def line(%{event: :picked} = e, _), do: "picked #{Dolphin.Fleet.VehicleSet.format(e.vehicles)} (#{e.requirement})"
  def line(%{event: :released} = e, _), do: "released #{Dolphin.Fleet.VehicleSet.format(e.vehicles)}"
  def line(%{event: :pick_failed} = e, _), do: "pick failed: #{e.reason}"
  def line(%{event: :mode_changed} = e, _), do: "vehicle #{e.vehicle} mode #{e.mode}"
  def line(%{event: :armed} = e, _), do: "vehicle #{e.vehicle} armed"
  def line(%{event: :disarmed} = e, _), do: "vehicle #{e.vehicle} disarmed"
  def line(%{event: :mission_uploaded} = e, _), do: "vehicle #{e.vehicle}: mission #{inspect(e.name)} uploaded (#{e.items} items)"
  def line(%{event: :mission_item_reached} = e, _), do: "vehicle #{e.vehicle} reached item #{e.seq}"
  def line(%{event: :condition_met} = e, _), do: "task #{e.task_id}: #{e.condition} holds"

  def line(%{event: :task_started, vehicle: v} = e, _) when v != nil, do: "task #{e.task_id} #{e.kind} #{inspect(e.name)} started on vehicle #{v}"

  def line(%{event: :task_finished, result: :failed} = e, _), do: "task #{e.task_id} #{e.kind} failed: #{e.reason}"

  # "stopped (the run's time (--for) is over)": the result is not said twice.
  def line(%{event: :task_finished, vehicle: v} = e, _) when v != nil,
    do: "task #{e.task_id} #{e.kind} #{inspect(e.name)} on vehicle #{v}: #{e.result}#{if e.reason, do: " (#{String.replace_prefix(e.reason, "stopped: ", "")})", else: ""}"

  def line(_event, _quiet), do: nil
end
