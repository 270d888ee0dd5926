defmodule Dolphin.Report do
  @moduledoc """
  A flight report: one self-contained HTML page (inline SVG, CSS and a few
  lines of script; it fetches nothing and opens offline) that shows what
  happened in a run, made from its telemetry log and, when given, its events.

      {:ok, summary} = Dolphin.Report.write("run.tlog", "run.jsonl", "report.html")
      summary.vehicles #=> [1, 2]

  From the shell: `mix dolphin.report RUN.tlog --events RUN.jsonl -o report.html`.

  The page has:

    * a **map**, in metres on a light grid, north up, with a scale bar: each
      vehicle's flown track (`GLOBAL_POSITION_INT`, simplified with
      Douglas–Peucker within 1 m) in its own colour, the missions uploaded
      to it (the ground station's `MISSION_ITEM_INT` in the log) as dashed
      paths, its home, take-off and landing points, where photos were taken
      (`CAMERA_IMAGE_CAPTURED`), and where it was when each of its tasks
      started and ended;
    * a **time line**, one lane per vehicle: a bar per task (name, kind, and
      its result — done, stopped, failed — with the reason on hover), marks
      for conditions met, mode changes, lost and reconnected, messages;
    * **plots** over time per vehicle: battery, height above home, ground
      speed, and link quality (the share of the autopilot's frames that
      arrived, from gaps in their sequence numbers);
    * a **summary**: per vehicle flight time, distance, mission items
      reached, photos, lowest battery, failed tasks with their reasons; and
      the script's result.

  Times are clock seconds from the start of the log: for a simulated run
  sped up K times, the speed-up is read from the vehicles' boot clocks, so
  the report shows the run's own time, as the events do.

  ## Damaged input

  A truncated or corrupt log gives a report of the frames that could be read
  and says how many bytes were skipped and why; unreadable lines of the events
  file are skipped and counted. A log with no MAVLink frame or no vehicle in
  it, and an events file with no event, are errors.

  ## Logs of several runs

  A log written by one run holds that run (`mix dolphin.run --tlog` replaces
  an existing file). A log that holds several — logs appended to one
  another, a link's `:tlog` given the same file run after run — is cut into
  its runs where the vehicles' boot clocks start again after a silence of
  the whole log (the ground station, which records its own heartbeat every
  second, was not running); the report shows one run, the last unless
  `:run` says which, and says so (`runs` and `run` in the summary). Runs
  of vehicles that kept running in between (real vehicles, whose clocks do
  not start again) cannot be told apart.

  ## Events of another run

  The events file carries no run id, so it is matched against the log by what
  both record: its vehicles must be in the log, its arming, mode changes and
  mission items reached must line up in time with the log's frames (which
  also places the events on the log's time line), and its time must be the
  log's: overlapping it, no longer than it, and a script that ended must end
  with the log (give the run's own log, as `mix dolphin.run --tlog` writes
  it, not a longer recording). Otherwise it is refused with reason
  `:events_mismatch`. Two runs alike in all of that — a deterministic
  simulation run twice — cannot be told apart.
  """

  alias Dolphin.Report.{Error, Events, FlightLog, HTML, Model}

  @typedoc "What a report holds, besides the page."
  @type summary :: %{
          path: Path.t(),
          bytes: non_neg_integer(),
          vehicles: [non_neg_integer()],
          span_s: float(),
          speedup: float(),
          frames: non_neg_integer(),
          bytes_skipped: non_neg_integer(),
          events: non_neg_integer() | nil,
          events_skipped: non_neg_integer(),
          script_result: String.t() | nil,
          runs: pos_integer(),
          run: pos_integer()
        }

  @doc """
  Reads `tlog_path` (and `events_path`, unless nil), writes the report to
  `out_path` and returns its summary. Options: `:title`, the page's heading
  (default "Flight report"); `:run`, which run of a log that holds several
  (from 1; default the last: see "Logs of several runs").
  """
  @spec write(Path.t(), Path.t() | nil, Path.t(), keyword()) :: {:ok, summary()} | {:error, Error.t()}
  def write(tlog_path, events_path, out_path, opts \\ []) when is_list(opts) do
    with {:ok, page, summary} <- build(tlog_path, events_path, opts) do
      case File.write(out_path, page) do
        :ok -> {:ok, %{summary | path: out_path, bytes: IO.iodata_length(page)}}
        {:error, why} -> {:error, %Error{reason: :write_failed, path: out_path, detail: to_string(:file.format_error(why))}}
      end
    end
  end

  @doc "Like `write/4`, but returns the page (iodata) and its summary (`path` nil) instead of writing it."
  @spec build(Path.t(), Path.t() | nil, keyword()) :: {:ok, iodata(), summary()} | {:error, Error.t()}
  def build(tlog_path, events_path, opts \\ []) when is_list(opts) do
    with {:ok, events, bad} <- read_events(events_path),
         {:ok, whole} <- read_log(tlog_path, Model.sensors(events)),
         {:ok, log, runs, run} <- select_run(whole, opts[:run], tlog_path),
         {:ok, timeline} <- Events.align(events, Model.anchors(log), events_path) do
      model = Model.build(log, events, timeline)
      title = Keyword.get(opts, :title, "Flight report")
      page = HTML.page(model, %{title: title, tlog: tlog_path, events: events_path, events_skipped: bad, runs: {runs, run}})

      {:ok, page,
       %{
         path: nil,
         bytes: IO.iodata_length(page),
         vehicles: Enum.map(model.vehicles, & &1.id),
         span_s: model.span_s,
         speedup: model.speedup,
         frames: log.stats.frames,
         bytes_skipped: log.stats.bytes_skipped,
         events: if(events_path, do: length(events)),
         events_skipped: bad,
         script_result: model.script && model.script.result,
         runs: runs,
         run: run
       }}
    end
  end

  # One run of the log: the one asked for, else the last.
  defp select_run(log, wanted, path) do
    n = length(FlightLog.runs(log))
    run = wanted || n

    if run in 1..n//1 do
      case FlightLog.select(log, run) do
        %FlightLog{vehicles: vs} when vs == %{} -> {:error, %Error{reason: :no_vehicles, path: path, detail: "run #{run} of #{n} has none"}}
        one -> {:ok, one, n, run}
      end
    else
      {:error, %Error{reason: :no_such_run, path: path, detail: "it holds #{n} run#{if n != 1, do: "s"}, there is no run #{run}"}}
    end
  end

  # The readings of the sensors the run declared are read too.
  defp read_log(path, sensors) do
    case FlightLog.read_file(path, sensors: Enum.map(sensors, & &1.source)) do
      {:ok, %FlightLog{stats: %{frames: 0, bytes: 0}}} ->
        {:error, %Error{reason: :no_frames, path: path, detail: "the file is empty"}}

      {:ok, %FlightLog{stats: %{frames: 0, bytes: bytes}}} ->
        {:error, %Error{reason: :no_frames, path: path, detail: "none of its #{bytes} bytes is a telemetry-log record (a .tlog as mix dolphin.run writes it?)"}}

      {:ok, %FlightLog{vehicles: vs, stats: stats}} when vs == %{} ->
        {:error, %Error{reason: :no_vehicles, path: path, detail: "#{stats.frames} frame(s) read, #{stats.bytes_skipped} of #{stats.bytes} bytes skipped"}}

      {:ok, log} ->
        {:ok, log}

      {:error, why} ->
        {:error, %Error{reason: :tlog_unreadable, path: path, detail: to_string(:file.format_error(why))}}
    end
  end

  defp read_events(nil), do: {:ok, [], 0}
  defp read_events(path), do: Events.read_file(path)
end
