defmodule Dolphin.Engine.OnSensor do
  @moduledoc """
  `on_sensor(%{v1 => m1, v2 => m2}, :smoke, above: 0.4, then: fn d -> t end)`:
  each vehicle flies its mission; when one of them reads the sensor above
  the threshold at a place farther than `apart` metres (default 100) from
  every detection already made, that is a detection
  (`Dolphin.Sensors.Detection`, and a `sensor_threshold` event naming the
  vehicle sent). The nearest vehicle not already looking at one is sent:
  its mission is stopped where it is (it holds), the task `then` makes of
  the detection runs on it, and when that task ends its mission goes on
  from where it stopped (`Dolphin.Mission.Resume`: a half-flown survey pass
  is flown again whole). The others fly on meanwhile. A detection made
  while every vehicle is looking is queued for the first one free. A
  vehicle whose mission has nothing left after its look (it was over, or
  the look came at its end) flies `finally` (a task: home, say), else
  stays where the look left it; a mission that cannot be resumed (it
  jumps, its home is unknown) fails the whole.

  Done once every mission is done (and the tasks `then` made); a failure
  of either fails it, stopping the rest. The missions' vehicles are reserved
  as each starts, not before the run.
  """
  use Dolphin.Engine.Task.Struct, missions: [], sensor: nil, above: nil, apart: 100.0, then: nil, finally: nil
  @behaviour Dolphin.Engine.Node

  import Dolphin.Engine.Node, only: [completed: 1]

  alias Dolphin.Engine.{Cond, Snapshot, Watcher}
  alias Dolphin.Sensors.{Detection, Sensor}

  @type t :: %__MODULE__{
          missions: [{Dolphin.Vehicles.Id.t(), Dolphin.Mission.t()}],
          sensor: Sensor.t(),
          above: number(),
          apart: number(),
          then: (Detection.t() -> term()),
          finally: Dolphin.Engine.Task.t() | nil
        }

  @impl true
  def kind, do: :on_sensor

  # State: the task; each vehicle's mission now (what a resume continues,
  # nil once done); what each vehicle does (:mission, :stopping, :making,
  # :looking, :resuming, :done); the progress it had reached when stopped;
  # the detection each stopped vehicle is for (`pending`); the places of
  # the detections made; those waiting for a vehicle (`queue`); whether a
  # helper is finding one (`finding`: :detect or :queue).
  @impl true
  def init(%__MODULE__{} = task) do
    st = %{
      task: task,
      current: Map.new(task.missions),
      doing: Map.new(task.missions, fn {v, _} -> {v, :mission} end),
      reached: %{},
      pending: %{},
      places: [],
      queue: [],
      finding: nil,
      detect: false,
      failed: nil
    }

    starts = for {v, m} <- task.missions, do: {:start_new, {:mission, v}, Dolphin.Engine.on(m, [v]), [v]}
    {starts ++ [watch(st)], st}
  end

  @impl true
  # Children stopped after a failure: the failure is the result.
  def handle({:finished, _key, _result}, %{failed: failed} = st) when failed != nil, do: {[], st}
  def handle({:code_result, _key, _result}, %{failed: failed} = st) when failed != nil, do: {[], st}

  # A detection: found, and the vehicle to send chosen, by a helper (live
  # reads); one helper at a time: while another runs, it is found after it.
  def handle({:condition, :detect}, %{finding: nil} = st), do: {[{:unwatch, :detect}, find(st)], %{st | finding: :detect}}
  def handle({:condition, :detect}, st), do: {[{:unwatch, :detect}], %{st | detect: true}}

  def handle({:code_result, :find, {:ok, nil}}, st), do: next(%{st | finding: nil}, [watch(st)])

  def handle({:code_result, :find, {:ok, {%Detection{} = d, sent}}}, st) do
    st = %{st | finding: nil, places: [d.position | st.places]}
    event = {:emit, :sensor_threshold, Detection.event_fields(d, source(st.task), sent)}

    {effects, st} =
      case sent do
        nil -> {[event, watch(st)], %{st | queue: st.queue ++ [d]}}
        v -> send_to(v, d, st, [event, watch(st)])
      end

    next(st, effects)
  end

  # A queued detection, and the nearest vehicle now free.
  def handle({:code_result, :nearest, {:ok, v}}, st) do
    [d | rest] = st.queue
    {effects, st} = send_to(v, d, %{st | queue: rest, finding: nil}, [])
    next(st, effects)
  end

  # Stopped to look: where it got to is read before anything else flies on it.
  def handle({:finished, {:mission, v}, result}, st) when :erlang.map_get(v, st.doing) == :stopping and not is_tuple(result),
    do: {[{:run_code, {:reached, v}, fn -> reached(v) end}], st}

  def handle({:finished, {:mission, _v}, {:failed, _} = failed}, st), do: fail_with(st, failed)
  def handle({:finished, {:mission, v}, _done}, st), do: next(%{st | doing: Map.put(st.doing, v, :done), current: Map.put(st.current, v, nil)}, [])

  def handle({:code_result, {:reached, v}, {:ok, reached}}, st), do: make(v, %{st | reached: Map.put(st.reached, v, reached)})

  def handle({:code_result, {:make, v}, {:ok, value}}, st) do
    case Dolphin.Engine.Taskable.impl_for(value) do
      nil -> after_look(v, st)
      _ -> {[{:start_new, {:look, v}, Dolphin.Engine.on(value, [v]), [v]}], %{st | doing: Map.put(st.doing, v, :looking)}}
    end
  end

  def handle({:finished, {:look, _v}, {:failed, _} = failed}, st), do: fail_with(st, failed)
  def handle({:finished, {:look, v}, _}, st), do: after_look(v, st)

  def handle({:code_result, {:resume, v}, {:ok, {:ok, rest, _seq}}}, st) do
    st = %{st | doing: Map.put(st.doing, v, :mission), current: Map.put(st.current, v, rest)}
    next(st, [{:start_new, {:mission, v}, Dolphin.Engine.on(rest, [v]), [v]}])
  end

  # Nothing left of it: the vehicle's mission is over.
  def handle({:code_result, {:resume, v}, {:ok, {:error, %Dolphin.Mission.Failure{cause: cause}}}}, st) when cause == :nothing_but_take_off or elem(cause, 0) == :nothing_left,
    do: over(v, %{st | current: Map.put(st.current, v, nil)})

  # One that cannot be resumed (it jumps, its home is unknown) fails the whole.
  def handle({:code_result, {:resume, _v}, {:ok, {:error, why}}}, st), do: fail_with(st, {:failed, why})

  def handle({:finished, {:finally, _v}, {:failed, _} = failed}, st), do: fail_with(st, failed)
  def handle({:finished, {:finally, v}, _}, st), do: next(%{st | doing: Map.put(st.doing, v, :done)}, [])

  def handle({:code_result, _key, {:error, reason}}, st), do: fail_with(st, {:failed, {:on_sensor_failed, reason}})

  # --- the steps ---

  # A flying vehicle is stopped first (it holds); one done goes at once;
  # one taken meanwhile leaves the detection queued, first.
  defp send_to(v, d, st, effects) do
    case st.doing[v] do
      :mission -> {effects ++ [{:stop, [{:mission, v}], {:sent_to_look, st.task.id}}], %{st | doing: Map.put(st.doing, v, :stopping), pending: Map.put(st.pending, v, d)}}
      :done -> make(v, %{st | pending: Map.put(st.pending, v, d)}, effects)
      _busy -> {effects, %{st | queue: [d | st.queue]}}
    end
  end

  defp make(v, st, effects \\ []) do
    {d, pending} = Map.pop(st.pending, v)
    then = st.task.then
    {effects ++ [{:run_code, {:make, v}, fn -> then.(d) end}], %{st | pending: pending, doing: Map.put(st.doing, v, :making)}}
  end

  defp after_look(v, st) do
    case st.current[v] do
      nil ->
        over(v, st)

      mission ->
        reached = st.reached[v]
        {[{:run_code, {:resume, v}, fn -> Dolphin.Mission.Platform.resume(mission, %{reached: reached}, v, v) end}], %{st | doing: Map.put(st.doing, v, :resuming)}}
    end
  end

  # A vehicle with nothing left of its mission after a look flies `finally`.
  defp over(v, %{task: %{finally: nil}} = st), do: next(%{st | doing: Map.put(st.doing, v, :done)}, [])
  defp over(v, st), do: {[{:start_new, {:finally, v}, Dolphin.Engine.on(st.task.finally, [v]), [v]}], %{st | doing: Map.put(st.doing, v, :finishing)}}

  # A vehicle free again takes the oldest queued detection; a detection
  # that came while a helper ran is found; with nothing to do and every
  # mission done, the whole is.
  defp next(st, effects) do
    free = free(st)

    cond do
      st.finding != nil ->
        {effects, st}

      st.queue != [] and free != [] ->
        at = hd(st.queue).position
        {effects ++ [{:run_code, :nearest, fn -> nearest(free, at) end}], %{st | finding: :queue}}

      st.detect ->
        {effects ++ [find(st)], %{st | finding: :detect, detect: false}}

      st.queue == [] and Enum.all?(st.doing, fn {_, what} -> what == :done end) ->
        {effects ++ [{:unwatch, :detect}, {:finish, :done}], st}

      true ->
        {effects, st}
    end
  end

  defp free(st), do: for({v, what} <- st.doing, what in [:mission, :done], do: v)

  defp fail_with(st, failed) do
    running = for {v, what} <- st.doing, what in [:mission, :stopping], do: {:mission, v}
    looking = for {v, :looking} <- st.doing, do: {:look, v}
    finishing = for {v, :finishing} <- st.doing, do: {:finally, v}
    {[{:unwatch, :detect}, {:stop, running ++ looking ++ finishing, :failed}, {:finish, completed(failed)}], %{st | failed: failed}}
  end

  # --- reading the vehicles ---

  defp watch(st), do: {:watch, :detect, detect_cond(st)}

  defp source(%__MODULE__{sensor: s, above: above}), do: "#{s.name} above #{above}"

  # Holds when a vehicle of the missions reads above the threshold, away from every detection made.
  defp detect_cond(%{task: task, places: places}) do
    ids = Enum.map(task.missions, &elem(&1, 0))
    Cond.new(fn snap -> Enum.any?(ids, &detected?(snap, &1, task, places)) end, source: source(task))
  end

  defp detected?(snap, id, task, places) do
    value = Snapshot.sensor(snap, id, task.sensor)
    position = Snapshot.position(snap, id)
    value != nil and value > task.above and away?(position, task, places)
  end

  defp away?(nil, _task, _places), do: false
  defp away?(position, task, places), do: Enum.all?(places, &(&1 == nil or Dolphin.Geo.distance(&1, position) > task.apart))

  # Live, in a helper: the detection (the highest reading above the
  # threshold away from every detection made, among those the vehicles
  # keep: the reading that made the condition hold is found even when the
  # vehicle has flown out of the smoke by the time the helper runs, as a
  # loaded host lets it) and the nearest vehicle free to look at it (nil:
  # none).
  defp find(st) do
    task = st.task
    ids = Enum.map(task.missions, &elem(&1, 0))
    free = free(st)
    places = st.places

    {:run_code, :find,
     fn ->
       # A reading older than the sensor's staleness is unknown, as in the condition.
       since = Dolphin.Clock.now_ms() - (task.sensor.stale_after || task.sensor.keep)

       ids
       |> Enum.flat_map(&Watcher.detections(&1, task.sensor))
       |> Enum.filter(&(&1.at_ms >= since))
       |> strongest(task, places)
       |> case do
         nil -> nil
         d -> {d, nearest(free, d.position)}
       end
     end}
  end

  @doc """
  Of `readings` (`Dolphin.Sensors.Detection`s: those the vehicles keep),
  the detection an `on_sensor` task makes: the highest above its threshold
  at a place farther than `apart` from every place in `places` (those of the
  detections made); `nil` when none is.
  """
  @spec strongest([Detection.t()], t(), [Dolphin.Geo.Location.t() | nil]) :: Detection.t() | nil
  def strongest(readings, %__MODULE__{} = task, places) do
    readings
    |> Enum.filter(&(&1.value != nil and &1.value > task.above and away?(&1.position, task, places)))
    |> Enum.max_by(& &1.value, fn -> nil end)
  end

  defp nearest([], _at), do: nil

  defp nearest(free, at), do: closest(Enum.map(free, &{&1, Snapshot.position(nil, &1)}), at)

  @doc """
  Of the vehicles free to look (`[{vehicle, its position or nil}]`, in the
  order the task names them: not one already looking), the one nearest
  `at`; the first when no position is known.
  """
  @spec closest([{term(), Dolphin.Geo.Location.t() | nil}, ...], Dolphin.Geo.Location.t()) :: term()
  def closest([{first, _} | _] = free, at) do
    free
    |> Enum.reject(fn {_, p} -> p == nil end)
    |> Enum.min_by(fn {_, p} -> Dolphin.Geo.distance(p, at) end, fn -> {first, nil} end)
    |> elem(0)
  end

  defp reached(v) do
    case Watcher.vehicle(v, :on_sensor).mission_progress do
      {reached, _total} -> reached
      nil -> nil
    end
  end
end
