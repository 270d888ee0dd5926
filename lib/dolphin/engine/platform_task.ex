defmodule Dolphin.Engine.PlatformTask do
  @moduledoc """
  A task of a platform (see `Dolphin.Engine.Platform`): `platform` is the
  module implementing the behaviour, `spec` its own description of the task.
  `vehicle` is filled in by the allocation when a run starts.
  """
  use Dolphin.Engine.Task.Struct, platform: nil, spec: nil, vehicle: nil
  @behaviour Dolphin.Engine.Node

  @type t :: %__MODULE__{platform: module(), spec: term(), vehicle: non_neg_integer() | nil}

  @doc false
  def kind(%__MODULE__{platform: p, spec: spec}) do
    Code.ensure_loaded(p)
    if function_exported?(p, :kind, 1), do: p.kind(spec), else: :platform
  end

  @impl true
  def kind, do: :platform

  @doc false
  def label(%__MODULE__{name: name}) when is_binary(name), do: name
  def label(%__MODULE__{platform: p, spec: spec}), do: p.name(spec)

  @doc false
  def requirements(%__MODULE__{platform: p, spec: spec}), do: p.requirements(spec) |> Map.new()

  # The node's state: the task and the last progress it reported, which a
  # failure carries (where another vehicle may take the task over).
  @impl true
  def init(task), do: {[:platform_start], %{task: task, progress: nil}}

  @impl true
  def handle({:platform, :done}, st), do: {[{:finish, :done}], st}
  def handle({:platform, {:failed, reason}}, st), do: fail(st, reason)
  def handle({:platform, {:progress, info}}, st), do: {[{:emit, :task_progress, %{vehicle: st.task.vehicle, progress: info}}], %{st | progress: info}}
  def handle({:platform, _other}, st), do: {[], st}
  def handle({:platform_start_failed, reason}, st), do: fail(st, reason)
  def handle({:platform_exit, reason}, st), do: fail(st, {:platform_exited, reason})

  def handle({:vehicle_lost, id}, st) do
    {effects, st} = fail(st, {:vehicle_lost, id})
    {[{:platform_stop, {:vehicle_lost, id}} | effects], st}
  end

  defp fail(st, reason), do: {[{:finish, {:failed, %{Dolphin.Engine.Runner.failure(st.task, reason) | progress: st.progress}}}], st}
end
