defmodule Dolphin.Engine.Watch do
  @moduledoc """
  `watch(t, on_error: handler)`: runs `t`; if it fails, the handler decides:

    * `:ignore` — `watch` completes;
    * `:propagate` — `watch` fails with the same failure (as if unwatched);
    * `fn failure -> ... end` — called with the `Dolphin.Engine.Failure`, in its
      own process; if it returns a task, that task runs (on the vehicles the
      failed task had, or others the script picked) and `watch` ends as it
      does; otherwise `watch` completes. A handler that raises fails `watch`;
    * `:reassign` (also written `reassign(t, from: set)`) — see below.

  ## Reassignment

  When a platform task inside `t` (a mission) fails because of its vehicle —
  the vehicle lost, or a failure the platform says is the vehicle's
  (`c:Dolphin.Engine.Platform.vehicle_fault?/1`: a battery failsafe, a
  refused arm) — the same task is given to another vehicle and resumed where
  the first one left it (`c:Dolphin.Engine.Platform.resume/4`; for missions,
  `Dolphin.Mission.Resume`). The new vehicle is the first, by system id, of
  the script's picked vehicles (or of `from:`) that is connected, meets the
  task's requirements, is not held by another run and runs no task now; a
  vehicle that failed the task is never given it again. The event
  `task_reassigned` (`run`, `task_id` of the failed task, `from`, `to`,
  `resume_seq`) comes before the new task starts, and `watch` then ends as
  the new task does (which may be reassigned again).

  If no vehicle can take it, `watch` fails with the first failure, its reason
  extended by why (`{:not_reassigned, reason, why}`). Any other failure is
  propagated. What followed the failed task inside `t` (in a sequence, say)
  does not run: `watch` ends with the reassigned task — put `reassign` around
  each mission whose loss is to be taken over.

  A lost vehicle whose task went to another one is not sent back into it
  should it be heard again: the platform holds it and reports it
  (`c:Dolphin.Engine.Platform.abandoned/2`; for missions a
  `vehicle_returned` event).
  """
  use Dolphin.Engine.Task.Struct, task: nil, on_error: :propagate, from: nil
  @behaviour Dolphin.Engine.Node

  import Dolphin.Engine.Node, only: [completed: 1]

  alias Dolphin.Engine.{Failure, PlatformTask, Reassign, Task}

  @type handler :: :ignore | :propagate | :reassign | (Failure.t() -> term())
  @type t :: %__MODULE__{task: Task.t(), on_error: handler(), from: Dolphin.Fleet.VehicleSet.t() | nil}

  @impl true
  def kind, do: :watch

  # State: the watch, the platform task running after a reassignment (nil
  # before), the vehicles that failed it, and the failure being handed over.
  @impl true
  def init(task), do: {[{:start, :t, task.task}], %{w: task, leaf: nil, failed: [], failure: nil}}

  @impl true
  def handle({:finished, :t, {:failed, _}}, %{w: %{on_error: :ignore}} = st), do: {[{:finish, :done}], st}
  def handle({:finished, :t, {:failed, _} = failed}, %{w: %{on_error: :propagate}} = st), do: {[{:finish, failed}], st}
  def handle({:finished, key, {:failed, f} = failed}, %{w: %{on_error: :reassign}} = st) when key in [:t, :handler], do: reassign(failed_leaf(key, f, st), f, failed, st)
  def handle({:finished, :t, {:failed, f}}, %{w: %{on_error: fun}} = st), do: {[{:run_code, :handler, fn -> fun.(f) end}], st}
  def handle({:finished, :t, _}, st), do: {[{:finish, :done}], st}

  def handle({:code_result, :handler, {:ok, value}}, st) do
    case Dolphin.Engine.Taskable.impl_for(value) do
      nil -> {[{:finish, :done}], st}
      _ -> {[{:start_new, :handler, value}], st}
    end
  end

  def handle({:code_result, :handler, {:error, reason}}, st), do: {[{:finish, {:failed, {:handler_failed, reason}}}], st}

  def handle({:code_result, :reassign, {:ok, {:ok, leaf, info}}}, st) do
    {[{:emit, :task_reassigned, Map.put(info, :task_id, st.failure.task_id)}, {:start_new, :handler, Dolphin.Engine.on(leaf, [info.to]), [info.to]}],
     %{st | leaf: leaf, failure: nil}}
  end

  def handle({:code_result, :reassign, {:ok, {:error, why}}}, st), do: not_reassigned(st, why)
  def handle({:code_result, :reassign, {:error, reason}}, st), do: not_reassigned(st, reason)
  def handle({:finished, :handler, result}, st), do: {[{:finish, completed(result)}], st}

  # The platform task of `t` that failed (after a reassignment, the one handed over).
  defp failed_leaf(:t, f, st), do: Enum.find(Task.flatten(st.w.task), &match?(%PlatformTask{id: id} when id == f.task_id, &1))
  defp failed_leaf(:handler, _f, st), do: st.leaf

  defp reassign(%PlatformTask{} = leaf, %Failure{vehicle: v} = f, failed, st) when v != nil do
    if Reassign.vehicle_fault?(leaf, f.reason) do
      lost = [v | st.failed]
      from = st.w.from
      watch_id = st.w.id
      {[{:run_code, :reassign, fn -> Reassign.plan(leaf, f, from, lost, watch_id) end}], %{st | failed: lost, failure: f}}
    else
      {[{:finish, failed}], st}
    end
  end

  defp reassign(_not_a_platform_task, _f, failed, st), do: {[{:finish, failed}], st}

  defp not_reassigned(%{failure: f} = st, why), do: {[{:finish, {:failed, %{f | reason: {:not_reassigned, f.reason, why}}}}], st}
end
