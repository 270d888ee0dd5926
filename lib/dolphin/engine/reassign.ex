defmodule Dolphin.Engine.Reassign do
  @moduledoc false
  # The engine's side of `reassign` (Dolphin.Engine.Watch): which failures are
  # the vehicle's, which vehicle takes a failed platform task over, and the
  # task it gets. plan/5 runs in the watch node's code helper: it asks the
  # fleet and the platform, which may take a while.

  alias Dolphin.Engine.{Context, Failure, PlatformTask}
  alias Dolphin.Fleet.{Allocation, VehicleSet}

  @doc false
  # Whether the platform counts the reason as its vehicle's doing.
  @spec vehicle_fault?(PlatformTask.t(), term()) :: boolean()
  def vehicle_fault?(_leaf, {:vehicle_lost, _}), do: true

  def vehicle_fault?(%PlatformTask{platform: p}, reason) do
    Code.ensure_loaded(p)
    function_exported?(p, :vehicle_fault?, 1) and p.vehicle_fault?(reason) == true
  end

  @doc false
  # {:ok, task for the new vehicle, %{from, to, resume_seq}} | {:error, why},
  # why a failure reason, worded by Dolphin.Engine.Failure.format_reason/1:
  # {:no_vehicle, set or nil, requirements}, {:cannot_resume, platform} or
  # the platform's own. `failed`: the vehicles that failed this task (never
  # given it again).
  @spec plan(PlatformTask.t(), Failure.t(), VehicleSet.t() | nil, [non_neg_integer()], integer()) ::
          {:ok, PlatformTask.t(), map()} | {:error, term()}
  def plan(%PlatformTask{platform: p, spec: spec} = leaf, %Failure{vehicle: from} = f, set, failed, watch_id) do
    ctx = Context.current()
    run = run_of(watch_id)
    Code.ensure_loaded(p)
    if match?({:vehicle_lost, _}, f.reason) and function_exported?(p, :abandoned, 2), do: p.abandoned(from, run: run, task_id: f.task_id, owner: ctx.owner)

    with {:ok, to} <- candidate(leaf, ctx, run, set, failed),
         {:ok, spec, seq} <- resume(p, spec, f.progress, from, to) do
      {:ok, %{leaf | spec: spec, id: nil, vehicle: nil}, %{from: from, to: to, resume_seq: seq}}
    end
  end

  defp resume(p, spec, progress, from, to) do
    if function_exported?(p, :resume, 4),
      do: p.resume(spec, progress, from, to),
      else: {:error, {:cannot_resume, p}}
  end

  # Connected, meeting the task's requirements, the script's (or held by this
  # run), among `set` if given, not held by another run, running no task now.
  defp candidate(leaf, ctx, run, set, failed) do
    requirements = PlatformTask.requirements(leaf)
    running = for %{vehicle: v} when v != nil <- Dolphin.Engine.tasks(), do: v
    allowed = if set, do: VehicleSet.ids(set)
    # The task as the allocation describes one (Dolphin.Fleet.Allocation.leaf).
    described = %{id: leaf.id, name: PlatformTask.label(leaf), requirements: requirements, allowed: allowed, path: []}

    found =
      for %{vehicle: view, picked_by: by, busy: busy} <- Dolphin.Fleet.vehicles(ctx.fleet),
          view.id not in failed,
          view.connected?,
          (by == ctx.owner and busy == nil) or busy == run,
          view.id not in running,
          Allocation.matches?(described, view),
          do: view.id

    case Enum.sort(found) do
      [to | _] ->
        {:ok, to}

      [] ->
        {:error, {:no_vehicle, allowed && set, requirements}}
    end
  end

  defp run_of(watch_id) do
    case Registry.lookup(Dolphin.Engine.Registry, {:task, watch_id}) do
      [{_pid, %{run: run}}] -> run
      [] -> nil
    end
  end
end
