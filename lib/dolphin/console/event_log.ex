defmodule Dolphin.Console.EventLog do
  @moduledoc false
  # The console's memory of events: the last `max` Dolphin.Events events
  # in a ring buffer (for events/1), and what each running task is doing,
  # from the events about it (for tasks/0). Started with the application,
  # so that a console opened mid-run still knows the run's beginning.

  use GenServer

  @default_max 1_000
  # Task states of tasks whose task_finished never came (a node killed
  # outright) must not pile up: the oldest ids go beyond this.
  @max_tasks 10_000

  @doc false
  def start_link(opts \\ []), do: GenServer.start_link(__MODULE__, opts, name: Keyword.get(opts, :name, __MODULE__))

  @doc false
  # The last `n` events, oldest first, that match `filter` (a function).
  @spec last(pos_integer(), (map() -> boolean()), GenServer.server()) :: [map()]
  def last(n, filter \\ fn _ -> true end, server \\ __MODULE__), do: GenServer.call(server, {:last, n, filter})

  @doc false
  # task_id => what the task is doing (text), for the tasks still running.
  @spec task_states(GenServer.server()) :: %{integer() => String.t()}
  def task_states(server \\ __MODULE__), do: GenServer.call(server, :task_states)

  @doc false
  # The clock time the buffer started at (event times are shown from it).
  @spec origin_ms(GenServer.server()) :: integer()
  def origin_ms(server \\ __MODULE__), do: GenServer.call(server, :origin)

  @impl true
  def init(opts) do
    # subscribe: false (tests) — the events are sent by hand.
    if Keyword.get(opts, :subscribe, true), do: Dolphin.Events.subscribe()
    {:ok, %{max: Keyword.get(opts, :max, @default_max), size: 0, buffer: :queue.new(), tasks: %{}, origin: Dolphin.Clock.now_ms()}}
  end

  @impl true
  def handle_call({:last, n, filter}, _from, s) do
    # Newest first until n are found, then back in order.
    found = s.buffer |> :queue.to_list() |> Enum.reverse() |> Stream.filter(&safe(filter, &1)) |> Enum.take(n) |> Enum.reverse()
    {:reply, found, s}
  end

  def handle_call(:task_states, _from, s), do: {:reply, s.tasks, s}
  def handle_call(:origin, _from, s), do: {:reply, s.origin, s}

  @impl true
  def handle_info({:dolphin, :events, event}, s) do
    {buffer, size} =
      if s.size >= s.max,
        do: {:queue.in(event, :queue.drop(s.buffer)), s.size},
        else: {:queue.in(event, s.buffer), s.size + 1}

    {:noreply, %{s | buffer: buffer, size: size, tasks: track(s.tasks, event)}}
  end

  def handle_info(_other, s), do: {:noreply, s}

  @doc false
  # Pure: the task states after one event.
  @spec track(map(), map()) :: map()
  def track(tasks, %{event: :task_finished, task_id: id}), do: Map.delete(tasks, id)

  def track(tasks, %{event: event, task_id: id} = e) when event in [:task_started, :task_progress, :condition_met] do
    tasks = Map.put(tasks, id, Dolphin.Console.Format.task_state(Map.get(tasks, id), e))
    if map_size(tasks) > @max_tasks, do: Map.delete(tasks, tasks |> Map.keys() |> Enum.min()), else: tasks
  end

  def track(tasks, _event), do: tasks

  defp safe(filter, event) do
    filter.(event)
  rescue
    _ -> false
  end
end
