defmodule Dolphin.Check.Recorder do
  @moduledoc false
  # Keeps what a pre-flight check's dry run learns: each mission a task
  # would fly (checked and estimated by Dolphin.Check.Mission when it
  # starts, with the battery the vehicle has then), whether each stand-in
  # vehicle is on the ground or in the air between missions, and where each
  # was when on the check's clock (its timeline, for Dolphin.Check.Separation).

  use GenServer

  alias Dolphin.Check.Finding
  alias Dolphin.Fleet.FakeSource

  @spec start_link(map()) :: GenServer.on_start()
  def start_link(args), do: GenServer.start_link(__MODULE__, args)

  # `now_ms`: the check's clock when it starts; `separation`: the script's
  # least separation (`min_separation`), if it set one.
  @spec mission(pid(), Dolphin.Mission.t(), non_neg_integer(), pos_integer() | nil, integer(), map() | nil) :: map() | nil
  def mission(recorder, mission, vehicle, line, now_ms, separation \\ nil),
    do: GenServer.call(recorder, {:mission, mission, vehicle, line, now_ms, separation})

  # Problems found as a flight went (its energy ones, if it was not cut short).
  @spec problems(pid(), [Dolphin.Check.Mission.problem()], pos_integer() | nil) :: :ok
  def problems(recorder, problems, line), do: GenServer.call(recorder, {:problems, problems, line})

  # Where a flight left its vehicle, and whether in the air, after
  # `elapsed_s` of flight (its path up to then is the vehicle's timeline).
  @spec ended(pid(), non_neg_integer(), Dolphin.Geo.Location.t() | nil, boolean(), float()) :: :ok
  def ended(recorder, vehicle, at, airborne?, elapsed_s), do: GenServer.cast(recorder, {:ended, vehicle, at, airborne?, elapsed_s})

  # {findings, estimates}, in the order the missions started.
  @spec results(pid()) :: {[Finding.t()], [map()]}
  def results(recorder), do: GenServer.call(recorder, :results)

  # The vehicles' timelines and the least separation the script asked for (nil: none).
  @spec timelines(pid()) :: {[Dolphin.Check.Separation.timeline()], map() | nil}
  def timelines(recorder), do: GenServer.call(recorder, :timelines)

  @impl true
  def init(args) do
    # args: test (the FakeSource name), file, limits, vehicles (id => %{payloads, home, airborne?})
    {:ok, Map.merge(args, %{findings: [], estimates: [], flights: %{}, timelines: %{}, separation: nil})}
  end

  @impl true
  def handle_call({:mission, mission, id, line, now_ms, separation}, _from, s) do
    fleet = Map.get(s.vehicles, id, %{payloads: [], home: nil, airborne?: false})

    battery =
      case FakeSource.vehicle(s.test, id),
        do:
          (
            {:ok, view} -> view.battery
            _ -> nil
          )

    vehicle = %{id: id, payloads: fleet.payloads, battery: battery, position: fleet.home, airborne?: fleet.airborne?, at: Map.get(fleet, :at), airframe: Map.get(fleet, :airframe)}
    {problems, energy, estimate} = Dolphin.Check.Mission.check(mission, vehicle, s.limits)
    estimate = estimate && Map.merge(estimate, %{line: line, energy: energy})
    # What the report keeps of an estimate (the flight needs the rest).
    estimates = if estimate, do: [Map.take(estimate, [:mission, :vehicle, :line, :length_m, :time_s, :battery_used, :battery_start, :ending]) | s.estimates], else: s.estimates
    s = if estimate, do: flown(s, id, mission.name, line, now_ms, estimate, vehicle), else: s
    s = if separation, do: %{s | separation: separation}, else: s
    {:reply, estimate, %{s | findings: Enum.reverse(findings(problems, s.file, line)) ++ s.findings, estimates: estimates}}
  end

  def handle_call({:problems, problems, line}, _from, s),
    do: {:reply, :ok, %{s | findings: Enum.reverse(findings(problems, s.file, line)) ++ s.findings}}

  def handle_call(:results, _from, s), do: {:reply, {Enum.reverse(s.findings), Enum.reverse(s.estimates)}, s}

  def handle_call(:timelines, _from, s) do
    # A flight still under way at the end is counted to where its estimate goes.
    s = Enum.reduce(Map.keys(s.flights), s, fn id, s -> close_flight(s, id, :all) end)

    timelines =
      for {id, t} <- s.timelines,
          do: %{vehicle: id, airframe: s.vehicles |> Map.get(id, %{}) |> Map.get(:airframe), points: Enum.reverse(t.points), missions: Enum.reverse(t.missions)}

    {:reply, {timelines, s.separation}, s}
  end

  # A flight begins: where it starts from, the estimate's path to come.
  defp flown(s, id, name, line, now_ms, estimate, vehicle) do
    t = Map.get(s.timelines, id, %{points: [], missions: []})
    t = %{t | points: [{now_ms, estimate.start_at, vehicle.airborne?} | t.points], missions: [{now_ms, name, line} | t.missions]}
    %{s | timelines: Map.put(s.timelines, id, t), flights: Map.put(s.flights, id, %{start_ms: now_ms, path: estimate.path})}
  end

  # Its path up to `elapsed_s` (or all of it) joins the vehicle's timeline,
  # ending where the flight stopped (`stop`, {at, airborne?}: part way
  # along to its next point).
  defp close_flight(s, id, elapsed_s, stop \\ nil) do
    case Map.pop(s.flights, id) do
      {nil, _} ->
        s

      {flight, flights} ->
        points = for {t, at, airborne?, _seq} <- flight.path, elapsed_s == :all or t <= elapsed_s, do: {flight.start_ms + round(t * 1000), at, airborne?}

        points =
          case stop do
            {%Dolphin.Geo.Location{} = at, airborne?} when is_number(elapsed_s) -> points ++ [{flight.start_ms + round(elapsed_s * 1000), at, airborne?}]
            _ -> points
          end

        timeline = Map.update!(s.timelines, id, fn t -> %{t | points: Enum.reverse(points, t.points)} end)
        %{s | flights: flights, timelines: timeline}
    end
  end

  defp findings(problems, file, line),
    do: for({severity, kind, message} <- problems, do: %Finding{severity: severity, kind: kind, file: file, line: line, message: message})

  @impl true
  def handle_cast({:ended, id, at, airborne?, elapsed_s}, s) do
    s = close_flight(s, id, elapsed_s, {at, airborne?})
    vehicles = Map.update(s.vehicles, id, %{payloads: [], home: nil, airborne?: airborne?, at: at}, &Map.merge(&1, %{airborne?: airborne?, at: at}))
    {:noreply, %{s | vehicles: vehicles}}
  end
end
