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

  @impl true
  def init(task), do: {[:platform_start], task}

  @impl true
  def handle({:platform, :done}, t), do: {[{:finish, :done}], t}
  def handle({:platform, {:failed, reason}}, t), do: {[{:finish, {:failed, reason}}], t}
  def handle({:platform, {:progress, info}}, t), do: {[{:emit, :task_progress, %{vehicle: t.vehicle, progress: info}}], t}
  def handle({:platform, _other}, t), do: {[], t}
  def handle({:platform_start_failed, reason}, t), do: {[{:finish, {:failed, reason}}], t}
  def handle({:platform_exit, reason}, t), do: {[{:finish, {:failed, {:platform_exited, reason}}}], t}

  def handle({:vehicle_lost, id}, t),
    do: {[{:platform_stop, {:vehicle_lost, id}}, {:finish, {:failed, {:vehicle_lost, id}}}], t}
end
