defmodule Dolphin.CLI.Run do
  @moduledoc """
  A compiled script run the way `mix dolphin.run` runs it: at the run's
  speed-up, with the vehicles it asks for (links, simulated vehicles, SITL
  instances or fake ones), its live output (`Dolphin.CLI.Renderer`) and
  events file, the script until it ends (or `--for`, or a signal, stops it),
  and a one-line summary; then all it started is stopped again.

      {:ok, script} = Dolphin.Script.compile("examples/single_vehicle.exs")
      Dolphin.CLI.Run.run(script, sim: 1, speedup: 50.0, for: "30m", for_ms: 1_800_000)
      #=> :stopped

  Options: those of `mix dolphin.run`, parsed (`:connect`, `:sim`, `:sitl`,
  `:sitl_bin`, `:sitl_defaults`, `:fake`, `:seed`, `:speedup`, `:for` and
  `:for_ms`, `:events`, `:tlog`, `:no_tlog`, `:forward`, `:quiet`, `:report`,
  `:web`, `:web_bind`, `:sname`, `:name`, `:cookie`, `:join`), and
  `:out`, `:err` (devices, default `:stdio` and `:stderr`), `:plain` (never
  the status block), `:ask` (the script's `ask/1`), `:signals` (SIGINT and
  SIGTERM stop the script, `Dolphin.CLI.Signals`) and `:sitl_extra` (more
  options of `Dolphin.SITL.start/2`).

  With `:report`, the flight report (`Dolphin.Report`) of the run's
  telemetry log and events file is written when the run has ended, and
  where is said on `:out` (a report that cannot be made is said on `:err`;
  the outcome stays the run's). With `:web`, a live view (`Dolphin.Web`)
  serves the run's page while it goes on.

  ## Outcomes

    * `:completed` — the script completed;
    * `:stopped` — `--for` (or `Dolphin.Script.stop/2`) stopped it: running
      tasks were stopped, vehicles hold;
    * `{:stopped, signal}` — SIGINT or SIGTERM stopped it the same way; a second one,
      later than `Dolphin.CLI.Signals.repeat_ms/0` after the first, ends
      the VM at once with `Dolphin.CLI.Signals.status/1`, once the log and
      the events file have what they were sent;
    * `:failed` — the script failed (what, where and why are printed on `:err`);
    * `{:error, %Dolphin.CommandLineError{reason: :failed}}` — its vehicles or outputs could
      not be started (a port in use, a SITL binary missing): nothing ran.
  """

  alias Dolphin.CLI.{Renderer, Signals, Teardown, Vehicles}
  alias Dolphin.Console.Format

  @type outcome :: :completed | :stopped | {:stopped, Signals.signal()} | :failed | {:error, Dolphin.CommandLineError.t()}

  # What the run undoes when it ends (Dolphin.CLI.Teardown) is tagged with
  # its kind: :output (stopped before the summary, which comes below them),
  # :vehicles and :signals.

  @doc """
  The pre-flight check (`Dolphin.Check`) that `mix dolphin.run` makes before
  it starts any vehicle: for `--sim N` and `--sitl N`, with N simulated
  copters as the fleet. A pack that would run empty is a warning here, not
  an error: the estimate is the simulator's model, and simulated copters
  (and SITL, with its own battery model) fly on at 0 %. Its findings are printed on `out` (nothing when there
  are none); `:refused` when it found errors. Skipped (`:ok`) with `--fake`
  (fake-platform tasks, no missions), with `--connect` or configured links
  (the fleet is known only once connected: `mix dolphin.check --connect`
  checks against it) and with `--no-check`.
  """
  @spec check(Dolphin.Script.t(), keyword(), IO.device()) :: :ok | :refused
  def check(script, opts, out) do
    n = opts[:sim] || opts[:sitl]

    cond do
      opts[:no_check] || opts[:fake] || n == nil ->
        :ok

      true ->
        # Simulated vehicles (and SITL's) fly on at 0 % and pass through
        # each other: what would be an error for real ones is said, as a warning.
        report = Dolphin.Check.check_script(script, fleet: stand_ins(n, opts[:home], opts[:fleet]), energy: :warning, separation: :warning)
        errors? = Dolphin.Check.errors?(report)

        if report.findings != [] and (errors? or !opts[:quiet]) do
          IO.write(out, Enum.map(report.findings, &(Dolphin.Check.Finding.format(&1) <> "\n")))
          if !errors?, do: IO.puts(out, "the pre-flight check found no error: flying")
        end

        if errors? do
          IO.puts(out, "the pre-flight check found errors: nothing flies (--no-check to fly anyway)")
          :refused
        else
          :ok
        end
    end
  end

  # The simulated fleet, carrying what the fleet file (--fleet) gives each
  # of its system ids besides the simulator's camera.
  defp stand_ins(n, home, nil), do: Dolphin.Check.sim_fleet(n, home)

  defp stand_ins(n, home, path) do
    given =
      case Vehicles.fleet_file(path) do
        {:ok, vehicles} -> Map.new(vehicles, &{&1.id, &1.payloads})
        {:error, _} -> %{}
      end

    for v <- Dolphin.Check.sim_fleet(n, home), do: %{v | payloads: Enum.sort(Enum.uniq(v.payloads ++ Map.get(given, v.id, [])))}
  end

  @doc "Runs `script` (see the options above) and says how it ended."
  @spec run(Dolphin.Script.t(), keyword()) :: outcome()
  def run(script, opts) do
    out = Keyword.get(opts, :out, :stdio)
    err = Keyword.get(opts, :err, :stderr)
    previous_speedup = Dolphin.Clock.speedup()
    if k = opts[:speedup], do: Dolphin.Clock.set_speedup(k)
    origin = Dolphin.Clock.now_ms()
    Teardown.begin()
    catch_signals(opts)
    opts = Keyword.put(opts, :tlog, Vehicles.tlog_path(opts, script.file))

    outcome =
      try do
        with {:ok, renderer} <- start_outputs(opts, origin, out),
             :ok <- start_web(opts, origin, out, script),
             :ok <- join_cluster(opts, out),
             :ok <- Vehicles.start(opts, out, &defer(&1, :vehicles)) do
          {result, signal} = run_until_signal(script, opts, renderer)
          # The log and the status block end before the summary is printed below them.
          Teardown.run(:output)
          summary(result, opts ++ [signal: signal, origin_ms: origin], out, err)
        end
      after
        # The outputs stop first (they show the run, not its teardown); then
        # the last started is the first stopped: the simulator before its link.
        Teardown.run(:output)
        # Released vehicles get their fence back before the links close.
        Dolphin.Vehicles.Fences.await_returns(30_000)
        Teardown.run_all()
        Dolphin.Clock.set_speedup(previous_speedup)
      end

    write_report(outcome, script, opts, out, err)
    outcome
  end

  # --report: once the vehicles and their links are stopped (the telemetry
  # log is whole) and the events file is closed. A report that cannot be
  # made is said on `err`; the run's outcome stays what it was.
  defp write_report({:error, _}, _script, _opts, _out, _err), do: :ok

  defp write_report(_outcome, script, opts, out, err) do
    if path = opts[:report] do
      case Dolphin.Report.write(opts[:tlog], opts[:events], path, title: "Flight report: " <> Path.basename(script.file)) do
        {:ok, summary} -> IO.puts(out, "flight report: #{Path.expand(path)} (#{length(summary.vehicles)} vehicle(s), #{Format.seconds(round(summary.span_s * 1000))} of clock time)")
        {:error, e} -> IO.puts(err, "no flight report: #{Exception.message(e)}")
      end
    end

    :ok
  end

  # --web PORT: the live view (Dolphin.Web) from the start of the run to the
  # end of its outputs; the run's process owns it.
  defp start_web(opts, origin, out, script) do
    case opts[:web] do
      nil ->
        :ok

      port ->
        bind = opts[:web_bind] || "127.0.0.1"

        case Dolphin.Web.start(port: port, bind: bind, title: "Live: " <> Path.basename(script.file), tlog: opts[:tlog], origin_ms: origin, owner: self()) do
          {:ok, web} ->
            defer(fn -> Dolphin.Web.stop(web) end, :output)
            unless opts[:quiet], do: IO.puts(out, "live view: #{Dolphin.Web.url(web)}")
            :ok

          {:error, e} ->
            {:error, Dolphin.CommandLineError.failed("--web #{port}", e)}
        end
    end
  end

  # --sname/--name and --join: distribution, then the stations joined (the
  # speed-up agreed with them); they are let go again when the run ends.
  defp join_cluster(opts, out) do
    case Dolphin.CLI.Cluster.start(opts, opts[:speedup]) do
      {:ok, lines} ->
        for node <- Dolphin.CLI.Cluster.joins(opts), do: defer(fn -> Dolphin.Cluster.Mirror.unfollow(String.to_atom(node)) end, :vehicles)
        unless opts[:quiet], do: Enum.each(lines, &IO.puts(out, &1))
        :ok

      {:error, e} ->
        {:error, e}
    end
  end

  # The script's result and the signal that stopped it (nil: none did).
  defp run_until_signal(script, opts, renderer) do
    # Fake vehicles (--fake) fly no MAVLink mission: each says so at once.
    platform_opts = if opts[:fake], do: Dolphin.Mission.Platform.refusing(:fake_vehicle), else: []
    {:ok, pid} = Dolphin.Script.start(script, [for: opts[:for_ms], platform_opts: platform_opts] ++ Keyword.take(opts, [:ask]))
    if opts[:signals], do: await_script(pid, renderer, nil), else: {Dolphin.Script.await(pid), nil}
  end

  defp await_script(pid, renderer, signal, hint \\ nil) do
    receive do
      {Dolphin.Script, ^pid, result} ->
        # A stop that ended before the hint leaves it unsaid.
        if hint, do: Process.cancel_timer(hint)
        receive do: (:signal_hint -> :ok), after: (0 -> :ok)
        {result, signal}

      {:dolphin_signal, sig} when signal == nil ->
        Dolphin.Script.stop(pid, {:signal, sig})
        # In the log, so that the status block stays whole below it.
        Renderer.note(renderer, "#{Signals.name(sig)}: stopping the script (tasks stop, vehicles hold)")
        # Until then another signal is a repeat of this one (Dolphin.CLI.Signals).
        await_script(pid, renderer, sig, Process.send_after(self(), :signal_hint, Signals.repeat_ms()))

      :signal_hint ->
        Renderer.note(renderer, "still stopping: Ctrl-C or SIGTERM again exits at once, without waiting for the stops")
        await_script(pid, renderer, signal)
    end
  end

  # From the start of the run to its end (teardown included), a first SIGINT
  # or SIGTERM comes to this process as a message: the script stops as with
  # `--for` (at once if it comes before the script starts). A repeat soon
  # after it changes nothing; a later one ends the run at once
  # (exit_at_once/4), with the status of that signal.
  defp catch_signals(opts) do
    if opts[:signals] do
      Signals.catch_signals(self())
      defer(&Signals.release_signals/0, :signals)
    end
  end

  # A second signal's last words: the log and the events file get what they
  # were sent (stopping them writes it), then the line that says why the run
  # ends without its summary. It runs in Dolphin.CLI.Signals' relay.
  defp exit_at_once(sig, renderer, writer, err) do
    Renderer.stop(renderer)

    if writer do
      try do
        Dolphin.Events.Writer.stop(writer)
      catch
        # Stopped already: the run was closing its outputs.
        :exit, _ -> :ok
      end
    end

    IO.puts(err, "#{Signals.name(sig)} again: exiting at once, without waiting for the stops")
  end

  defp start_outputs(opts, origin, out) do
    # On a terminal the log scrolls above a status block redrawn in place;
    # elsewhere (pipes, CI, files) it is plain timestamped lines.
    terminal = if !opts[:quiet] && !opts[:plain], do: Renderer.terminal(out)
    {:ok, renderer} = Renderer.start_link(out: out, origin_ms: origin, quiet: opts[:quiet] == true, terminal: terminal)
    defer(fn -> Renderer.stop(renderer) end, :output)

    err = Keyword.get(opts, :err, :stderr)

    with {:ok, writer} <- start_writer(opts[:events], origin, err),
         {:ok, log} <- start_tlog(opts[:tlog]) do
      if opts[:signals], do: Signals.catch_signals(self(), again: &exit_at_once(&1, renderer, writer, err))
      if log && !opts[:quiet], do: IO.puts(out, log)
      {:ok, renderer}
    end
  end

  # The links append to the log (several links share one); emptied first, it
  # holds this run only, so that its report is this run's.
  defp start_tlog(nil), do: {:ok, nil}

  defp start_tlog(path), do: Dolphin.CLI.OutputFile.start_log(path)

  defp start_writer(nil, _origin, _err), do: {:ok, nil}

  defp start_writer(path, origin, err) do
    # A writer that cannot open its file stops in its init, and its exit
    # would take this process with it: trapped while it starts, it is a
    # message, and the run ends with what went wrong instead.
    trapping = Process.flag(:trap_exit, true)

    try do
      case Dolphin.Events.Writer.start_link(path: path, origin_ms: origin) do
        {:ok, writer} ->
          defer(
            fn ->
              with {:error, :timeout} <- Dolphin.Events.Writer.stop(writer),
                   do: IO.puts(err, "--events #{path}: still writing after 5 minutes, stopped: the file may lack the run's last events")
            end,
            :output
          )

          {:ok, writer}

        {:error, why} ->
          # (It exits right after saying so; the bound only keeps a surprise from hanging the run.)
          receive do
            {:EXIT, _writer, ^why} -> :ok
          after
            5_000 -> :ok
          end

          {:error, Dolphin.CommandLineError.failed("--events", why)}
      end
    after
      Process.flag(:trap_exit, trapping)
    end
  end

  defp defer(fun, kind), do: Teardown.defer(fun, kind)

  # Times on the run's clock, the events' (from the start of the run, its
  # vehicles' start included): the summary's time is its last event's.
  defp summary({:ok, %{result: :done} = s}, opts, out, _err) do
    IO.puts(out, "script completed after #{Format.seconds(ended(s, opts))} of clock time")
    :completed
  end

  defp summary({:ok, %{result: :stopped} = s}, opts, out, _err) do
    why =
      case opts[:signal] do
        nil -> if opts[:for_ms], do: "--for #{opts[:for]} is over, counted from the script's start at #{Format.seconds(s.started_ms - opts[:origin_ms])}", else: "stopped"
        sig -> Signals.name(sig)
      end

    IO.puts(out, "script stopped after #{Format.seconds(ended(s, opts))} of clock time (#{why}): running tasks were stopped, vehicles hold")
    if sig = opts[:signal], do: {:stopped, sig}, else: :stopped
  end

  defp summary({:error, %Dolphin.Script.Error{} = e}, _opts, _out, err) do
    IO.puts(err, Dolphin.Script.Error.format(e))
    :failed
  end

  defp ended(summary, opts), do: summary.started_ms + summary.duration_ms - opts[:origin_ms]
end
