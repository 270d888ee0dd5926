defmodule Dolphin.Engine.Watch do
  @moduledoc """
  `watch(t, on_error: handler)`: runs `t`; if it fails, the handler decides:

    * `:ignore` — `watch` completes;
    * `:propagate` — `watch` fails with the same failure (as if unwatched);
    * `fn failure -> ... end` — called with the `Dolphin.Engine.Failure`, in its
      own process; if it returns a task, that task runs (on the vehicles the
      failed task had, or others the script picked) and `watch` ends as it
      does; otherwise `watch` completes. A handler that raises fails `watch`.
  """
  use Dolphin.Engine.Task.Struct, task: nil, on_error: :propagate
  @behaviour Dolphin.Engine.Node

  import Dolphin.Engine.Node, only: [completed: 1]

  @type handler :: :ignore | :propagate | (Dolphin.Engine.Failure.t() -> term())
  @type t :: %__MODULE__{task: Dolphin.Engine.Task.t(), on_error: handler()}

  @impl true
  def kind, do: :watch
  @impl true
  def init(task), do: {[{:start, :t, task.task}], task}

  @impl true
  def handle({:finished, :t, {:failed, _}}, %{on_error: :ignore} = w), do: {[{:finish, :done}], w}
  def handle({:finished, :t, {:failed, _} = failed}, %{on_error: :propagate} = w), do: {[{:finish, failed}], w}
  def handle({:finished, :t, {:failed, f}}, %{on_error: fun} = w), do: {[{:run_code, :handler, fn -> fun.(f) end}], w}
  def handle({:finished, :t, _}, w), do: {[{:finish, :done}], w}

  def handle({:code_result, :handler, {:ok, value}}, w) do
    case Dolphin.Engine.Taskable.impl_for(value) do
      nil -> {[{:finish, :done}], w}
      _ -> {[{:start_new, :handler, value}], w}
    end
  end

  def handle({:code_result, :handler, {:error, reason}}, w), do: {[{:finish, {:failed, {:handler_failed, reason}}}], w}
  def handle({:finished, :handler, result}, w), do: {[{:finish, completed(result)}], w}
end
