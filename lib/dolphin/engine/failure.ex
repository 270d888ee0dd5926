defmodule Dolphin.Engine.Failure do
  @moduledoc """
  Why a task failed: which task (`task_id`, `kind`, `name`, and `meta` with
  the script `line`), on which vehicle (platform tasks), and the `reason`.
  A failure travels up unchanged, so the failure of a whole run names the task
  where it began.

      iex> f = %Dolphin.Engine.Failure{task_id: 7, kind: :mission, name: "Survey", vehicle: 2, reason: {:vehicle_lost, 2}, meta: %{line: 12}}
      iex> Dolphin.Engine.Failure.message(f)
      ~s[mission "Survey" (task 7, line 12) on vehicle 2 failed: vehicle 2 lost]

  Reasons the engine gives: `{:exception, exception, stacktrace}`,
  `{:exit, reason}`, `{:throw, value}` (code that raised, exited or threw),
  `{:condition_error, source, exception}`, `{:vehicle_lost, id}`,
  `{:platform_exited, reason}`, `{:stop_timeout, ms}`, `{:stop_failed, reason}`,
  `{:handler_failed, reason}`, `{:crashed, reason}`, a
  `Dolphin.Fleet.AllocationError`, `{:not_reassigned, reason, why}` (a
  `reassign` that could not hand the task over: `why` is
  `{:no_vehicle, vehicle_set_or_nil, requirements}` when no vehicle
  among its `from:` set, or the script's, could take it,
  `{:cannot_resume, platform}`, or what the platform or the code said);
  platforms give
  their own, as data: an exception that words itself (a mission's
  `Dolphin.Mission.Failure`), which says whether the vehicle caused it (a
  failsafe, a refused arm: `reassign` takes those over,
  `c:Dolphin.Engine.Platform.vehicle_fault?/1`); the fake platform's
  `{:vehicle_fault, text}` is such a failure too.

  `progress` is the last progress a platform task reported before it failed
  (nil if none): where another vehicle may take it over.
  """

  defstruct task_id: nil, kind: nil, name: nil, vehicle: nil, meta: %{}, reason: nil, progress: nil

  @type t :: %__MODULE__{
          task_id: integer() | nil,
          kind: atom(),
          name: String.t() | nil,
          vehicle: non_neg_integer() | nil,
          meta: map(),
          reason: reason(),
          progress: map() | nil
        }

  @typedoc "The reasons the engine gives (see the moduledoc)."
  @type engine_reason ::
          {:exception, Exception.t(), Exception.stacktrace()}
          | {:exit, term()}
          | {:throw, term()}
          | {:condition_error, String.t(), Exception.t()}
          | {:vehicle_lost, Dolphin.Vehicles.Id.t()}
          | {:platform_exited, term()}
          | {:stop_timeout, non_neg_integer()}
          | {:stop_failed, reason()}
          | {:handler_failed, reason()}
          | {:crashed, term()}
          | {:not_reassigned, reason(), reason() | {:no_vehicle, Dolphin.Fleet.VehicleSet.t() | nil, Dolphin.Engine.Platform.requirements()} | {:cannot_resume, module()}}

  @typedoc """
  Why a task failed: the engine's own reasons, a platform's exception that
  words itself (`Dolphin.Mission.Failure`, `Dolphin.Fleet.AllocationError`,
  `Dolphin.ManoeuvreError`), or whatever else a platform of a user's gives
  (`c:Dolphin.Engine.Platform.stop/2` and its task's exits are the
  platform's to define: worded with `inspect/1` when nothing else fits).
  """
  @type reason :: engine_reason() | Exception.t() | {:vehicle_fault, String.t()} | term()

  @doc "A one-line explanation."
  @spec message(t()) :: String.t()
  def message(%__MODULE__{} = f) do
    where = Enum.join(Enum.reject(["task #{f.task_id}", f.meta[:line] && "line #{f.meta[:line]}"], &(&1 in [nil, false])), ", ")
    name = if f.name, do: " #{inspect(f.name)}", else: ""
    vehicle = if f.vehicle, do: " on vehicle #{f.vehicle}", else: ""
    "#{f.kind}#{name} (#{where})#{vehicle} failed: #{format_reason(f.reason)}"
  end

  @doc "A reason (of a failure or of a stop) as text."
  @spec format_reason(term()) :: String.t()
  def format_reason({:exception, e, _stack}), do: format_exception(e)
  def format_reason({:exit, reason}) when reason in [:killed, :shutdown], do: exit_words(reason)
  def format_reason({:exit, reason}), do: "exited: #{inspect(reason)}"
  def format_reason({:throw, value}), do: "threw #{inspect(value)}"
  def format_reason({:condition_error, source, e}), do: "condition `#{source}` raised #{format_exception(e)}"
  def format_reason({:vehicle_lost, id}), do: "vehicle #{id} lost"
  def format_reason({:vehicle_fault, text}), do: text
  def format_reason({:not_reassigned, reason, why}), do: "#{format_reason(reason)}; no other vehicle could take it over: #{format_reason(why)}"

  def format_reason({:no_vehicle, set, requirements}) do
    among = if set, do: "among #{Dolphin.Fleet.VehicleSet.format(set)}", else: "among the vehicles the script picked"
    "no vehicle #{among} is connected, free and meets its requirements#{requirement_words(requirements)}"
  end

  def format_reason({:cannot_resume, platform}), do: "#{inspect(platform)} cannot resume its tasks on another vehicle"
  def format_reason({:platform_exited, reason}), do: "its process #{exit_words(reason)} without reporting"
  def format_reason({:stop_timeout, ms}), do: "did not stop within #{ms} ms of clock time (killed)"
  def format_reason({:stop_failed, reason}), do: "could not be stopped: #{format_reason(reason)}"
  def format_reason({:handler_failed, reason}), do: "the on_error handler failed: #{format_reason(reason)}"
  def format_reason({:crashed, :start_timeout}), do: "engine process crashed: its subtree did not start in time (killed)"
  def format_reason({:crashed, :no_report_after_stop}), do: "engine process crashed: it did not report after it was stopped (killed)"
  def format_reason({:crashed, reason}), do: "engine process #{exit_words(reason)}"
  def format_reason({:condition_met, id}), do: "stopped: the condition of task #{id} held"
  def format_reason({:sent_to_look, id}), do: "stopped: on_sensor (task #{id}) sent its vehicle to look at a detection; the mission goes on afterwards"
  def format_reason({:on_sensor_failed, reason}), do: "on_sensor's then: failed: #{format_reason(reason)}"
  def format_reason({:time_limit, id}), do: "stopped: time limit of task #{id}"
  def format_reason({:sibling_failed, _}), do: "stopped: a concurrent task failed"
  def format_reason({:parent_exit, reason}), do: "stopped: what started it #{parent_words(reason)}"
  def format_reason({:signal, :sigint}), do: "stopped: the run was interrupted (SIGINT, Ctrl-C)"
  def format_reason({:signal, :sigterm}), do: "stopped: the run was terminated (SIGTERM)"
  def format_reason(:stopped), do: "stopped: the task above it ended"
  def format_reason(:halted), do: "stopped: the script halted"
  def format_reason(:operator), do: "stopped by the operator"
  def format_reason(:shutdown), do: "stopped: shutting down"
  def format_reason(:deadline), do: "stopped: the run's time (--for) is over"
  def format_reason(%__MODULE__{} = f), do: message(f)
  # A platform's failure as data (a mission's Dolphin.Mission.Failure, an
  # allocation's error) words itself.
  def format_reason(%_{__exception__: true} = e), do: Exception.message(e)
  def format_reason(text) when is_binary(text), do: text
  # A reason no one foresaw: the term itself is the most truthful text.
  def format_reason(other), do: inspect(other, charlists: :as_lists)

  @doc """
  How a process ended, in words (`Dolphin.ExitReason.words/2`, with the
  engine's own words for what a shutdown carries).

      iex> Dolphin.Engine.Failure.exit_words(:killed)
      "was killed"
      iex> Dolphin.Engine.Failure.exit_words({:shutdown, :deadline})
      "was shut down (stopped: the run's time (--for) is over)"
      iex> Dolphin.Engine.Failure.exit_words({:badmatch, 3})
      "crashed ({:badmatch, 3})"
  """
  @spec exit_words(term()) :: String.t()
  def exit_words(reason), do: Dolphin.ExitReason.words(reason, &format_reason/1)

  # The parent's end: a parent that ended normally was stopped (a script's code at its end).
  defp parent_words(:normal), do: "ended"
  defp parent_words(:killed), do: "was stopped"
  defp parent_words(reason), do: exit_words(reason)

  defp format_exception(%_{__exception__: true} = e), do: "#{inspect(e.__struct__)}: #{Exception.message(e)}"
  defp format_exception(other), do: inspect(other)

  defp requirement_words(req) do
    case Enum.filter(
           [req[:type] && "type #{inspect(req[:type])}", req[:airframe] && "airframe #{inspect(req[:airframe])}", req[:payloads] not in [nil, []] && "payloads #{inspect(req[:payloads])}"],
           & &1
         ) do
      [] -> ""
      said -> " (" <> Enum.join(said, ", ") <> ")"
    end
  end
end

defmodule Dolphin.Engine.TaskError do
  @moduledoc "Raised by `Dolphin.Engine.execute!/2` (and the script's `execute`) when the task fails."
  defexception [:failure]

  @impl true
  def message(%{failure: f}), do: Dolphin.Engine.Failure.message(f)
end
