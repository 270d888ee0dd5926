defmodule Dolphin.Report.Error do
  @moduledoc """
  Why a flight report could not be made (`Dolphin.Report.write/4`).

  `reason` is one of:

    * `:tlog_unreadable` — the telemetry log cannot be opened or read;
    * `:no_frames` — the log holds no MAVLink frame (an empty file, or not
      a telemetry log);
    * `:no_vehicles` — the log holds frames, but none of a vehicle;
    * `:no_such_run` — the run asked for is not in the log;
    * `:no_events` — the events file holds no event that can be read;
    * `:events_unreadable` — the events file cannot be read;
    * `:events_mismatch` — the events are from another run (see
      `Dolphin.Report`);
    * `:write_failed` — the report cannot be written.

  `path` is the file concerned, `detail` says more.
  """

  defexception [:reason, :path, :detail]

  @type reason :: :tlog_unreadable | :no_frames | :no_vehicles | :no_such_run | :events_unreadable | :no_events | :events_mismatch | :write_failed
  @type t :: %__MODULE__{reason: reason(), path: Path.t() | nil, detail: String.t() | nil}

  @impl true
  def message(%__MODULE__{reason: reason, path: path, detail: detail}) do
    what =
      case reason do
        :tlog_unreadable -> "cannot read the telemetry log"
        :no_frames -> "no MAVLink frame in the telemetry log"
        :no_vehicles -> "no vehicle in the telemetry log"
        :no_such_run -> "no such run in the telemetry log"
        :no_events -> "no event in the events file"
        :events_unreadable -> "cannot read the events"
        :events_mismatch -> "the events do not belong to the telemetry log"
        :write_failed -> "cannot write the report"
      end

    Enum.join(Enum.reject([what, path, detail], &is_nil/1), ": ")
  end
end
