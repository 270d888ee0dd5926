defmodule Dolphin.Engine.Platform do
  @moduledoc """
  The behaviour of a platform: what runs one-vehicle tasks (MAVLink missions,
  the fake platform), as Dolphin's plugins do. The engine knows nothing else
  of vehicles.

  A platform task is `%Dolphin.Engine.PlatformTask{platform: module, spec: term}`
  (see `Dolphin.Engine.platform_task/3`); `spec` is the platform's own value
  (a `%Dolphin.Mission{}`), usually made usable in scripts by implementing
  `Dolphin.Engine.Taskable` for it.

  ## Life of a platform task

  1. Before a run, `c:requirements/1` tells the allocation what vehicle the
     task needs; the engine picks one (see `Dolphin.Engine` on allocation).
  2. `c:start/3` is called in the engine's leaf process with the spec, the
     vehicle's system id and options (`:owner` — the leaf's pid, `:run`,
     `:task_id`, `:clock` — the `Dolphin.Engine.TimeSource` to use for
     timers, `:source` — the `Dolphin.Fleet.Source`). It returns promptly
     with `{:ok, pid}`: a process **linked to the caller** (start it with
     `start_link`) that does the work — upload, arm, fly.
  3. The process reports to `owner` with `done/1`, `failed/2` and any number
     of `progress/2` before that, then exits (normally). A process that exits
     without reporting fails the task with its exit reason.
  4. To stop it (`until`, `during`, `one_of`, a failed sibling, the operator,
     the vehicle lost), the engine calls `c:stop/2` (or sends
     `c:stop_request/1`) from the leaf process and waits for it to return, at most the run's stop timeout (15 s of clock
     time by default; then the process is killed and the task fails). `stop`
     returns once the vehicle is safe — for a mission: holding position — and
     the process is gone or going. Reasons: `{:condition_met, task_id}`,
     `{:time_limit, task_id}`, `{:sibling_failed, key}`, `{:vehicle_lost, id}`,
     `:operator`, `{:parent_exit, reason}`, `:shutdown`, and when a script
     ends early `:deadline` (`--for`), `:halted`, `{:signal, :sigint | :sigterm}`
     (`Dolphin.Engine.Failure.format_reason/1` says each in words)
  5. If the engine's leaf dies without calling `stop` (killed), the link
     delivers an exit signal: a platform whose vehicle must not fly on blind
     traps exits and makes it safe on `{:EXIT, owner, reason}`.

  A vehicle lost while its task runs fails the task: the engine calls `stop`
  with `{:vehicle_lost, id}` (a platform may return at once) and reports the
  failure.

  ## Example

  `Dolphin.Engine.FakePlatform` is a complete, small platform.
  """

  @type spec :: term()
  @type vehicle_type :: :uav | :ugv | :usv | :uuv | :other
  @typedoc "`type` (one class or a list), `airframe` (one or a list, `Dolphin.Vehicles.View.airframes/0`), `payloads` (all required), `id` (one system id)."
  @type requirements :: %{
          optional(:type) => vehicle_type() | [vehicle_type()] | nil,
          optional(:airframe) => Dolphin.Vehicles.View.airframe() | [Dolphin.Vehicles.View.airframe()] | nil,
          optional(:payloads) => [atom()],
          optional(:id) => non_neg_integer() | nil
        }

  @doc "The task's name in events, errors and the console (a mission's name)."
  @callback name(spec()) :: String.t()

  @doc "The kind of task in events (`:mission`); default `:platform`."
  @callback kind(spec()) :: atom()

  @doc "What vehicle the task needs."
  @callback requirements(spec()) :: requirements()

  @doc "Starts the task on a vehicle: a process linked to the caller. See the module doc."
  @callback start(spec(), vehicle :: non_neg_integer(), opts :: keyword()) :: {:ok, pid()} | {:error, term()}

  @doc "Stops the task's process; returns when its vehicle is safe. See the module doc."
  @callback stop(pid(), reason :: term()) :: :ok | {:error, term()}

  @doc """
  The request the task's process answers to stop, when that process is a
  `GenServer` or a `:gen_statem` that handles the call `stop/2` makes
  (`{:stop, reason}`, say). The engine then sends it from the leaf as a
  request (`:gen_server.send_request/2`) and waits for the reply, bounded
  by the stop timeout, instead of calling `c:stop/2` in a helper process:
  one process less for each stop, which a burst of conditions tripped at
  once feels. The reply is what `c:stop/2` returns; a process gone before
  it replied counts as stopped (it had finished or failed).
  """
  @callback stop_request(reason :: term()) :: term()

  @doc """
  Whether a failure reason is the vehicle's doing (lost, a failsafe, a
  refused arm) rather than the task's: `reassign` hands only those over to
  another vehicle. Without it, only `{:vehicle_lost, id}` is.
  """
  @callback vehicle_fault?(reason :: term()) :: boolean()

  @doc """
  The task as another vehicle (`to`) goes on with it where the failed one
  (`from`) left it, from the last `progress` it reported (nil if none):
  `{:ok, spec, resume_seq}` (the point it goes on from, for the
  `task_reassigned` event), or `{:error, why}` (text). Called in a helper
  process of the engine. Without it, `reassign` cannot hand the platform's
  tasks over.
  """
  @callback resume(spec(), progress :: map() | nil, from :: non_neg_integer(), to :: non_neg_integer()) ::
              {:ok, spec(), non_neg_integer()} | {:error, String.t()}

  @doc """
  The task of the lost `vehicle` went to another vehicle: should it be heard
  again, it must not go on with the task (a MAVLink vehicle that was only out
  of range still flies its mission) but be made safe and reported. Options:
  `:run`, `:task_id` (the failed task), `:owner` (the script: nothing is
  watched once it has ended).
  """
  @callback abandoned(vehicle :: non_neg_integer(), opts :: keyword()) :: :ok

  @optional_callbacks kind: 1, stop_request: 1, vehicle_fault?: 1, resume: 4, abandoned: 2

  @doc "Reports progress (a map, shown in `task_progress` events) to the engine."
  @spec progress(pid(), map()) :: :ok
  def progress(owner, info) when is_map(info), do: send(owner, {:dolphin_platform, self(), {:progress, info}}) && :ok

  @doc "Reports the task done; the process then exits."
  @spec done(pid()) :: :ok
  def done(owner), do: send(owner, {:dolphin_platform, self(), :done}) && :ok

  @doc "Reports the task failed, with a reason (a term or an exception); the process then exits."
  @spec failed(pid(), term()) :: :ok
  def failed(owner, reason), do: send(owner, {:dolphin_platform, self(), {:failed, reason}}) && :ok
end
