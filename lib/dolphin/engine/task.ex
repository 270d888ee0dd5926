defmodule Dolphin.Engine.Task do
  @moduledoc """
  The task model: tasks are plain data, one struct per kind, built by the
  functions of `Dolphin.Engine` (or the script macros) and run by the engine.

  | struct | built by | children |
  | --- | --- | --- |
  | `Dolphin.Engine.Idle` | `idle(d)` | — |
  | `Dolphin.Engine.Action` | `action(fun)` | — |
  | `Dolphin.Engine.Condition` | `condition(c)` | — |
  | `Dolphin.Engine.PlatformTask` | `platform_task(module, spec)` (a mission, ...) | — |
  | `Dolphin.Engine.Sequence` | `t1 >>> t2`, `sequence([...])` | the tasks, in order |
  | `Dolphin.Engine.Concurrent` | `t1 \\|\\|\\| t2`, `concurrent([...])` | the tasks |
  | `Dolphin.Engine.On` | `on(t, set)` | `t` |
  | `Dolphin.Engine.Until` | `until(t, c)` | `t` |
  | `Dolphin.Engine.During` | `during(d, t)` | `t` |
  | `Dolphin.Engine.WaitFor` | `wait_for(c)`, `wait_for(c, then: t)` | `t`, if any |
  | `Dolphin.Engine.OneOf` | `one_of([{c1, t1}, ...])` | the branches' tasks |
  | `Dolphin.Engine.AllOf` | `all_of([{c1, t1}, ...])` | the branches' tasks |
  | `Dolphin.Engine.Watch` | `watch(t, on_error: ...)`, `reassign(t)` | `t` |

  Every struct has `id` (given when a run starts: tasks are values, the same
  one may run many times), `name` (optional, see `Dolphin.Engine.named/2`)
  and `meta` (`%{file, line}` where the script wrote it). `inspect/1` shows a
  task as the script would write it.

      iex> import Dolphin.Engine
      iex> inspect(sequence([idle(1000), concurrent([idle(5), idle(6)])]))
      "#Task<idle(1000) >>> (idle(5) ||| idle(6))>"
  """

  alias Dolphin.Engine.{Action, AllOf, Concurrent, Condition, During, Idle, On, OneOf, OnSensor, PlatformTask, Sequence, Until, WaitFor, Watch}

  @type t ::
          Idle.t()
          | Action.t()
          | Condition.t()
          | PlatformTask.t()
          | Sequence.t()
          | Concurrent.t()
          | On.t()
          | Until.t()
          | During.t()
          | WaitFor.t()
          | OneOf.t()
          | AllOf.t()
          | Watch.t()
          | OnSensor.t()

  @doc "Converts a value to a task with `Dolphin.Engine.Taskable`; `ArgumentError` if it is not one."
  @spec new!(term()) :: t()
  def new!(value) do
    Dolphin.Engine.Taskable.to_task(value)
  rescue
    Protocol.UndefinedError ->
      raise ArgumentError,
            "not a task: #{inspect(value)} (tasks are built by idle/action/condition/mission/... " <>
              "or anything implementing Dolphin.Engine.Taskable)"
  end

  @doc "The kind of a task, as in events (`:until`, `:sequence`, ... or a platform's kind)."
  @spec kind(t()) :: atom()
  def kind(%PlatformTask{} = t), do: PlatformTask.kind(t)
  def kind(%module{}), do: module.kind()

  @doc "The direct subtasks."
  @spec children(t()) :: [t()]
  def children(%Sequence{tasks: ts}), do: ts
  def children(%Concurrent{tasks: ts}), do: ts
  def children(%On{task: t}), do: [t]
  def children(%Until{task: t}), do: [t]
  def children(%During{task: t}), do: [t]
  def children(%WaitFor{then: nil}), do: []
  def children(%WaitFor{then: t}), do: [t]
  def children(%OneOf{branches: bs}), do: Enum.map(bs, &elem(&1, 1))
  def children(%AllOf{branches: bs}), do: Enum.map(bs, &elem(&1, 1))
  def children(%Watch{task: t}), do: [t]
  def children(_leaf), do: []

  @doc "Replaces the direct subtasks (same number, same order)."
  @spec put_children(t(), [t()]) :: t()
  def put_children(%Sequence{} = t, ts), do: %{t | tasks: ts}
  def put_children(%Concurrent{} = t, ts), do: %{t | tasks: ts}
  def put_children(%On{} = t, [c]), do: %{t | task: c}
  def put_children(%Until{} = t, [c]), do: %{t | task: c}
  def put_children(%During{} = t, [c]), do: %{t | task: c}
  def put_children(%WaitFor{then: nil} = t, []), do: t
  def put_children(%WaitFor{} = t, [c]), do: %{t | then: c}
  def put_children(%OneOf{branches: bs} = t, ts), do: %{t | branches: Enum.zip_with(bs, ts, fn {c, _}, x -> {c, x} end)}
  def put_children(%AllOf{branches: bs} = t, ts), do: %{t | branches: Enum.zip_with(bs, ts, fn {c, _}, x -> {c, x} end)}
  def put_children(%Watch{} = t, [c]), do: %{t | task: c}
  def put_children(leaf, []), do: leaf

  @doc "Applies `fun` to every task of the tree, children first."
  @spec postwalk(t(), (t() -> t())) :: t()
  def postwalk(task, fun), do: fun.(put_children(task, Enum.map(children(task), &postwalk(&1, fun))))

  @doc "Every task of the tree, parents before children, in order."
  @spec flatten(t()) :: [t()]
  def flatten(task), do: [task | Enum.flat_map(children(task), &flatten/1)]

  @doc "How many tasks the tree has."
  @spec count(t()) :: pos_integer()
  def count(task), do: 1 + Enum.sum(Enum.map(children(task), &count/1))

  @doc "Gives every task of the tree an id, from `first` in pre-order; returns the tree and the next free id."
  @spec number(t(), integer()) :: {t(), integer()}
  def number(task, first) do
    {children, next} = Enum.map_reduce(children(task), first + 1, &number/2)
    {put_children(%{task | id: first}, children), next}
  end

  @doc "The name events and errors give a task: its own, or a short description."
  @spec label(t()) :: String.t()
  def label(%{name: name}) when is_binary(name), do: name
  def label(%PlatformTask{} = t), do: PlatformTask.label(t)
  def label(task) do
    text = format(task)
    if String.length(text) > 80, do: String.slice(text, 0, 79) <> "…", else: text
  end

  @doc "A task as a script would write it."
  @spec format(t()) :: String.t()
  def format(task), do: fmt(task, 0)

  # Precedence: 0 top, 1 inside |||, 2 inside >>>.
  defp fmt(%Sequence{tasks: ts}, prec), do: paren(Enum.map_join(ts, " >>> ", &fmt(&1, 2)), prec > 1)
  defp fmt(%Concurrent{tasks: ts}, prec), do: paren(Enum.map_join(ts, " ||| ", &fmt(&1, 1)), prec > 0)
  defp fmt(%Idle{duration: d}, _), do: "idle(#{d})"
  defp fmt(%Action{name: nil}, _), do: "action(...)"
  defp fmt(%Action{name: n}, _), do: "action(#{inspect(n)})"
  defp fmt(%Condition{cond: c}, _), do: "condition(#{c.source})"
  defp fmt(%PlatformTask{} = t, _), do: PlatformTask.label(t) |> inspect()
  defp fmt(%On{task: t, vehicles: v}, _), do: "on(#{fmt(t, 0)}, #{Dolphin.Fleet.VehicleSet.format(v)})"
  defp fmt(%Until{task: t, cond: c}, _), do: "until(#{fmt(t, 0)}, #{c.source})"
  defp fmt(%During{task: t, duration: d}, _), do: "during(#{d}, #{fmt(t, 0)})"
  defp fmt(%WaitFor{cond: c, then: nil}, _), do: "wait_for(#{c.source})"
  defp fmt(%WaitFor{cond: c, then: t}, _), do: "wait_for(#{c.source}, then: #{fmt(t, 0)})"
  defp fmt(%OneOf{branches: bs}, _), do: "one_of(" <> Enum.map_join(bs, "; ", fn {c, t} -> "#{c.source} -> #{fmt(t, 0)}" end) <> ")"
  defp fmt(%AllOf{branches: bs}, _), do: "all_of(" <> Enum.map_join(bs, "; ", fn {c, t} -> "#{c.source} -> #{fmt(t, 0)}" end) <> ")"
  defp fmt(%Watch{task: t, on_error: :reassign, from: nil}, _), do: "reassign(#{fmt(t, 0)})"
  defp fmt(%Watch{task: t, on_error: :reassign, from: set}, _), do: "reassign(#{fmt(t, 0)}, from: #{Dolphin.Fleet.VehicleSet.format(set)})"
  defp fmt(%OnSensor{} = t, _),
    do: "on_sensor(%{" <> Enum.map_join(t.missions, ", ", fn {v, m} -> "#{v} => #{inspect(m.name)}" end) <> "}, #{inspect(t.sensor.name)}, above: #{t.above})"

  defp fmt(%Watch{task: t, on_error: e}, _), do: "watch(#{fmt(t, 0)}, on_error: #{if is_function(e), do: "fn", else: inspect(e)})"

  defp paren(s, true), do: "(" <> s <> ")"
  defp paren(s, false), do: s

  @doc false
  # Inspect for every task struct.
  def inspect_task(task, _opts) do
    case task.name do
      nil -> "#Task<#{format(task)}>"
      name -> "#Task<#{inspect(name)}: #{format(task)}>"
    end
  end
end
