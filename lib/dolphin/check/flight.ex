defmodule Dolphin.Check.Flight do
  @moduledoc false
  # A mission "flown" by a pre-flight check's stand-in vehicle: it passes the
  # mission's estimated time on the check's clock, tick by tick, draining the
  # vehicle's battery as the estimate says (so that `until(..., battery(v) < 0.3)` and
  # the like react as they would), then completes — or, for a mission that
  # never ends by itself, keeps hovering until stopped. Stopped, it answers
  # at once, as Dolphin.Mission.Executor's stop does (a call {:stop, reason}).

  use GenServer, restart: :temporary

  alias Dolphin.Fleet.FakeSource

  # Clock time between two battery updates.
  @tick_ms 10_000
  # Holding drain per second with no estimate to say its airframe's
  # (Dolphin.Check.Mission's copter: 30 A of 3300 mAh).
  @hover_per_s 30.0 / 3.6 / 3300.0

  @spec start_link(map()) :: GenServer.on_start()
  def start_link(args), do: GenServer.start_link(__MODULE__, args)

  @impl true
  def init(args) do
    # Linked to the engine's leaf: its exit is ours.
    {:ok, view} = FakeSource.vehicle(args.test, args.vehicle)
    clock = args.clock || Dolphin.Check.Clock
    e = args.estimate
    start_battery = view.battery || 1.0
    hold_per_s = (e && e.hold_per_s) || @hover_per_s
    rate = if e && e.time_s > 0, do: e.battery_used / e.time_s, else: hold_per_s
    finite? = e != nil and match?({kind, _} when kind in [:landing, :reached], e.ending)
    airborne? = (view.relative_altitude || 0.0) > 1.0

    s =
      %{args | clock: clock}
      |> Map.merge(%{elapsed_s: 0.0, started_ms: clock.now_ms(), battery: start_battery, rate: rate, hold_per_s: hold_per_s, finite?: finite?, time_s: (e && e.time_s) || 0.0, airborne?: airborne?})

    clock.send_after(self(), :tick, min(@tick_ms, round(s.time_s * 1000)))
    {:ok, s}
  end

  @impl true
  # The flight's time moves by whole ticks, not by the clock's reading: the
  # battery a condition saw must be the one a stop leaves.
  def handle_info(:tick, s) do
    elapsed_s = if s.finite?, do: min(s.elapsed_s + @tick_ms / 1000, s.time_s), else: s.elapsed_s + @tick_ms / 1000
    s = %{s | elapsed_s: elapsed_s}

    cond do
      s.finite? and elapsed_s >= s.time_s ->
        drain(s, s.time_s)
        if s.estimate, do: Dolphin.Check.Recorder.problems(s.recorder, s.estimate.energy, s.estimate.line)
        left_at(s, s.time_s)
        Dolphin.Engine.Platform.done(s.owner)
        {:stop, :normal, s}

      true ->
        drain(s, elapsed_s)
        s.clock.send_after(self(), :tick, @tick_ms)
        {:noreply, s}
    end
  end

  def handle_info(_other, s), do: {:noreply, s}

  @impl true
  def handle_call({:stop, _reason}, _from, s) do
    drain(s, s.elapsed_s)
    # Cut short: the pack running out before the stop is still an error. Judged
    # at the clock's time of the stop: a clock that moved on while this process
    # waited for a core (its patience, on a loaded machine) leaves its ticks behind.
    stopped_s = max(s.elapsed_s, (s.clock.now_ms() - s.started_ms) / 1000)
    if s.estimate && s.battery - used(s, stopped_s) <= 0.0, do: Dolphin.Check.Recorder.problems(s.recorder, [empty_before_stop(s)], s.estimate.line)

    left_at(s, s.elapsed_s)
    {:stop, :normal, :ok, s}
  end

  # Where the flight is after `elapsed_s` (the vehicle holds there when
  # stopped): that far along the way from the last point of the estimate's
  # path reached by then to the next, as Dolphin.Check.Separation draws it —
  # an approximation where a point's time includes a loiter, a delay or a
  # take-off's lead. (Placed at the last point reached, two surveys stopped
  # 80 s into 3 km legs that part at their first corner stood together
  # there, and flew home and landed as one: the check saw one conflict, at
  # the corner.)
  defp left_at(%{estimate: nil} = s, elapsed_s), do: Dolphin.Check.Recorder.ended(s.recorder, s.vehicle, nil, false, elapsed_s)

  defp left_at(s, elapsed_s) do
    {at, airborne?} = position_at(s.estimate, s.airborne?, elapsed_s)
    if at, do: FakeSource.set(s.test, s.vehicle, position: at, relative_altitude: if(airborne?, do: 20.0, else: 0.0))
    Dolphin.Check.Recorder.ended(s.recorder, s.vehicle, at, airborne?, elapsed_s)
  end

  @doc false
  # {where, in the air?} `elapsed_s` into flying estimate `e`, which starts
  # on the ground or in the air (`airborne?`): its path as a timeline.
  @spec position_at(map(), boolean(), float()) :: {Dolphin.Geo.Location.t() | nil, boolean()}
  def position_at(e, airborne?, elapsed_s) do
    points = for {t, %Dolphin.Geo.Location{} = at, flies?, _seq} <- [{0.0, e.start_at, airborne?, 0} | e.path], do: {round(t * 1000), at, flies?}

    case points do
      [] -> {nil, airborne?}
      points -> Dolphin.Check.Separation.position(points, round(elapsed_s * 1000))
    end
  end

  defp empty_before_stop(%{estimate: e} = s) do
    empty_s =
      cond do
        s.rate * s.time_s >= s.battery -> s.battery / s.rate
        s.hold_per_s > 0 -> s.time_s + (s.battery - s.rate * s.time_s) / s.hold_per_s
        true -> s.time_s
      end

    # The item it would be flying to then, if it is still on its first way through.
    seq = if empty_s <= s.time_s, do: Enum.find_value(e.path, fn {end_s, _, _, seq} -> if end_s >= empty_s, do: seq end)

    where =
      case {seq, e.ending} do
        {seq, _} when is_integer(seq) and seq > 0 -> " (on its way to item #{seq})"
        {_, {:loops_forever, _}} -> " (going round its loop)"
        {_, {:loiter_forever, seq}} -> " (loitering at item #{seq})"
        _ -> ""
      end

    {:error, :energy,
     "mission #{inspect(e.mission)} on vehicle #{s.vehicle}: starting with #{round(s.battery * 100)} %, the pack would be empty after #{round(empty_s)} s of flight#{where}, before anything stopped it"}
  end

  # Past the mission's end an endless one holds (a copter hovers, a plane circles, a rover stands).
  defp used(s, elapsed_s), do: s.rate * min(elapsed_s, s.time_s) + s.hold_per_s * max(elapsed_s - s.time_s, 0.0)

  defp drain(s, elapsed_s) do
    left = max(s.battery - used(s, elapsed_s), 0.0)
    FakeSource.set(s.test, s.vehicle, battery: left)
    left
  end
end
