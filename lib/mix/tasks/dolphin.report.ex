defmodule Mix.Tasks.Dolphin.Report do
  @shortdoc "Makes an HTML flight report of a run from its .tlog (and events)"

  @moduledoc """
  Makes a flight report of a run: one self-contained HTML page with a map of
  where each vehicle flew against what was planned, a time line of its tasks,
  plots of battery, height, speed and link quality, and a summary table (see
  `Dolphin.Report` for what it shows and how it reads its input).

      mix dolphin.run examples/two_vehicles.exs --sim 2 --speedup 30 --for 10m --tlog run.tlog --events run.jsonl
      mix dolphin.report run.tlog --events run.jsonl -o run.html

  ## Options

    * `--events FILE` — the run's events (`mix dolphin.run --events FILE`):
      tasks, conditions and the script's result; without it the report shows
      what the log alone tells
    * `-o FILE`, `--output FILE` — where to write the page (default: the
      log's name with `.html`); `-o -` writes it to standard output (and
      the line that says what it holds to standard error)
    * `--run N` — of a log that holds several runs, the `N`th (from 1;
      default the last)

  A damaged log still gives a report, which says what was skipped; events of
  another run are refused; a log or an events file with nothing readable in
  it (no MAVLink frame, no event) is an error. A log that holds several runs
  (logs appended to one another: see `Dolphin.Report`) gives the report of
  one of them, never of several at once, and says so.

  ## Exit status

  As every task's (README.md, "Exit status"): 1 — no report (a log with no
  vehicle in it or nothing readable, events of another run or no event, a
  report that cannot be written); 2 — bad usage (an unknown option, no log
  given, a log or events file that does not exist, `-o` in a missing
  directory, `--run 0`).
  """

  use Mix.Task

  @switches [events: :string, output: :string, run: :integer]
  @aliases [o: :output]
  @usage "usage: mix dolphin.report RUN.tlog [--events RUN.jsonl] [-o REPORT.html] [--run N]"

  @impl Mix.Task
  def run(args) do
    Dolphin.CLI.Signals.exit_on_signal("dolphin.report", "no report was written")
    # A closed pipe (`| head`) ends the task at once, quietly.
    Dolphin.CLI.Stdout.watch()

    case OptionParser.parse(args, strict: @switches, aliases: @aliases) do
      {opts, [tlog], []} ->
        # The report reads the MAVLink dialect only: no vehicles, links or clock.
        Mix.Task.run("compile", [])
        out = opts[:output] || Path.rootname(tlog, ".tlog") <> ".html"

        if out != "-" do
          with {:error, message} <- Dolphin.CLI.OutputFile.check(if(opts[:output], do: "-o", else: "the report"), out),
               do: Mix.raise("dolphin.report: #{message}\n" <> @usage, exit_status: 2)
        end

        if opts[:run] != nil and opts[:run] < 1, do: Mix.raise("dolphin.report: --run takes a run's number, from 1, got #{opts[:run]}\n" <> @usage, exit_status: 2)

        case make(tlog, opts[:events], out, Keyword.take(opts, [:run])) do
          {:ok, line} -> if out == "-", do: IO.puts(:stderr, line), else: Mix.shell().info(line)
          {:error, error} -> Mix.raise("dolphin.report: " <> Exception.message(error), exit_status: status(error))
        end

      {_, _, [{switch, _} | _]} ->
        Mix.raise("dolphin.report: unknown or malformed option #{switch}\n" <> @usage, exit_status: 2)

      {_, _, []} ->
        Mix.raise(@usage, exit_status: 2)
    end
  end

  # A log or events file that is not there: the command line named the wrong
  # one (README.md, "Exit status").
  defp status(%Dolphin.Report.Error{reason: reason, path: path}) when reason in [:tlog_unreadable, :events_unreadable],
    do: if(path && File.exists?(path), do: 1, else: 2)

  defp status(_error), do: 1

  @doc """
  Writes the report (`out` `"-"`: to standard output) and returns the line
  the task prints. Option: `:run` (see `Dolphin.Report.write/4`).
  """
  @spec make(Path.t(), Path.t() | nil, Path.t(), keyword()) :: {:ok, String.t()} | {:error, Dolphin.Report.Error.t()}
  def make(tlog, events, out, opts \\ []) do
    with {:ok, s} <- write(tlog, events, out, opts) do
      damaged = if s.bytes_skipped > 0, do: "; the log is damaged: #{s.bytes_skipped} bytes skipped (see the report)", else: ""
      skipped = if s.events_skipped > 0, do: "; #{s.events_skipped} unreadable event line(s) skipped", else: ""

      runs =
        if s.runs > 1,
          do: "\nthe telemetry log holds #{s.runs} runs (the vehicles' clocks started again after the ground station had stopped recording): " <>
                "this report is of run #{s.run}#{if s.run == s.runs, do: ", the last", else: ""}, alone (--run N for another)",
          else: ""

      {:ok,
       "report: #{if out == "-", do: "standard output", else: out} (#{div(s.bytes + 1023, 1024)} KiB): #{length(s.vehicles)} vehicle(s), #{s.frames} frames, " <>
         "#{round(s.span_s)} s of clock time" <> if(s.events, do: ", #{s.events} events", else: "") <> damaged <> skipped <> runs}
    end
  end

  defp write(tlog, events, "-", opts) do
    with {:ok, page, summary} <- Dolphin.Report.build(tlog, events, opts) do
      IO.binwrite(:stdio, page)
      {:ok, summary}
    end
  end

  defp write(tlog, events, out, opts), do: Dolphin.Report.write(tlog, events, out, opts)
end
