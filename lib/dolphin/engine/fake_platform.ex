defmodule Dolphin.Engine.FakePlatform do
  @moduledoc """
  A platform whose tasks only pass time: each runs for a scripted duration and
  then completes or fails, reports scripted progress, and takes a scripted
  time to stop. For tests, benchmarks and dry runs of a script's logic
  (`mix dolphin.run --fake N`); a complete example of `Dolphin.Engine.Platform`.

      survey = Dolphin.Engine.FakePlatform.task("survey", duration: 30_000, type: :uav, notify: self())
      Dolphin.Engine.run(until(survey, battery(v) < 0.3) >>> idle(1000))

  Options of `task/2`: `:duration` (clock ms or `:infinity`, default 1000),
  `:result` (`:done` or `{:fail, reason}`), `:type`, `:payloads`, `:id`
  (requirements), `:progress` (`[{after_ms, map}]`), `:stop_ms` (clock time
  the stop takes, default 0), `:stop_result` (`:ok` or `{:error, reason}`),
  `:notify` (a pid that gets `{:fake_platform, event, info}` for
  `:started`, `:stopped`, `:finished` and `:abandoned` — the leaf died
  without stopping it — with `info` a map of `name`, `vehicle`, `task_id`,
  `pid`, `reason`, `at` (`System.monotonic_time/0` when it happened)).

  Under `reassign`, a task whose fake vehicle is lost (or that fails with
  `{:vehicle_fault, text}`) runs again whole on another one.
  """

  use GenServer, restart: :temporary

  @behaviour Dolphin.Engine.Platform

  defstruct name: "test", duration: 1_000, result: :done, type: nil, payloads: [], id: nil, progress: [], stop_ms: 0, stop_result: :ok, notify: nil

  @type t :: %__MODULE__{}

  @doc "A fake-platform task (see the module doc for options)."
  @spec task(String.t(), keyword()) :: t()
  def task(name, opts \\ []) when is_binary(name) do
    t = struct!(%__MODULE__{name: name}, opts)

    unless t.duration == :infinity or (is_integer(t.duration) and t.duration >= 0),
      do: raise(ArgumentError, "duration must be clock milliseconds or :infinity, got: #{inspect(t.duration)}")

    unless t.result == :done or match?({:fail, _}, t.result),
      do: raise(ArgumentError, "result must be :done or {:fail, reason}, got: #{inspect(t.result)}")

    t
  end

  defimpl Dolphin.Engine.Taskable do
    def to_task(t), do: Dolphin.Engine.platform_task(Dolphin.Engine.FakePlatform, t)
  end

  @impl Dolphin.Engine.Platform
  def name(%__MODULE__{name: name}), do: name

  @impl Dolphin.Engine.Platform
  def kind(_spec), do: :test

  @impl Dolphin.Engine.Platform
  def requirements(t), do: %{type: t.type, payloads: t.payloads, id: t.id}

  # A fake vehicle's failure `{:vehicle_fault, text}` is its own, as a mission's failsafe is.
  @impl Dolphin.Engine.Platform
  def vehicle_fault?({:vehicle_fault, _text}), do: true
  def vehicle_fault?(_reason), do: false

  # Taken over, a test task runs again whole, as it was written (it has no
  # items to skip); its `resume_seq` is the `:reached` of its last progress, or 0.
  @impl Dolphin.Engine.Platform
  def resume(%__MODULE__{} = t, progress, _from, _to), do: {:ok, t, (progress && progress[:reached]) || 0}

  @impl Dolphin.Engine.Platform
  def start(%__MODULE__{} = t, vehicle, opts), do: GenServer.start_link(__MODULE__, {t, vehicle, Map.new(opts)})

  @impl Dolphin.Engine.Platform
  def stop(pid, reason) do
    GenServer.call(pid, {:stop, reason}, :infinity)
  catch
    # Already over (it finished as it was being stopped): nothing to stop.
    :exit, _ -> :ok
  end

  @impl Dolphin.Engine.Platform
  def stop_request(reason), do: {:stop, reason}

  @impl GenServer
  def init({t, vehicle, opts}) do
    # Linked to the engine's leaf: an exit from it means the leaf died without stopping us.
    Process.flag(:trap_exit, true)
    clock = Map.get(opts, :clock, Dolphin.Engine.TimeSource.Clock)
    timers = for {after_ms, info} <- t.progress, do: clock.send_after(self(), {:progress, info}, after_ms)
    timers = if t.duration != :infinity, do: [clock.send_after(self(), :finish, t.duration) | timers], else: timers
    s = %{t: t, vehicle: vehicle, owner: opts.owner, clock: clock, task_id: Map.get(opts, :task_id), timers: timers}
    notify(s, :started, nil)
    {:ok, s}
  end

  @impl GenServer
  def handle_info(:finish, s) do
    case s.t.result do
      :done -> Dolphin.Engine.Platform.done(s.owner)
      {:fail, reason} -> Dolphin.Engine.Platform.failed(s.owner, reason)
    end

    notify(s, :finished, s.t.result)
    {:stop, :normal, s}
  end

  def handle_info({:progress, info}, s) do
    Dolphin.Engine.Platform.progress(s.owner, info)
    {:noreply, s}
  end

  def handle_info({:reply_stop, from}, s) do
    GenServer.reply(from, s.t.stop_result)
    {:stop, :normal, s}
  end

  def handle_info({:EXIT, owner, reason}, %{owner: owner} = s) do
    notify(s, :abandoned, reason)
    {:stop, :normal, s}
  end

  def handle_info(_other, s), do: {:noreply, s}

  @impl GenServer
  def handle_call({:stop, reason}, from, s) do
    notify(s, :stopped, reason)
    Enum.each(s.timers, &s.clock.cancel/1)

    if s.t.stop_ms > 0 do
      s.clock.send_after(self(), {:reply_stop, from}, s.t.stop_ms)
      {:noreply, s}
    else
      {:stop, :normal, s.t.stop_result, s}
    end
  end

  defp notify(%{t: %{notify: nil}}, _event, _reason), do: :ok

  defp notify(s, event, reason),
    do: send(s.t.notify, {:fake_platform, event, %{name: s.t.name, vehicle: s.vehicle, task_id: s.task_id, pid: self(), reason: reason, at: System.monotonic_time()}})
end
