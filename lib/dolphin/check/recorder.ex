defmodule Dolphin.Check.Recorder do
  @moduledoc false
  # Keeps what a pre-flight check's dry run learns: each mission a task
  # would fly (checked and estimated by Dolphin.Check.Mission when it
  # starts, with the battery the vehicle has then), and whether each
  # stand-in vehicle is on the ground or in the air between missions.

  use GenServer

  alias Dolphin.Check.Finding
  alias Dolphin.Fleet.FakeSource

  @spec start_link(map()) :: GenServer.on_start()
  def start_link(args), do: GenServer.start_link(__MODULE__, args)

  @spec mission(pid(), Dolphin.Mission.t(), non_neg_integer(), pos_integer() | nil) :: map() | nil
  def mission(recorder, mission, vehicle, line), do: GenServer.call(recorder, {:mission, mission, vehicle, line})

  # Problems found as a flight went (its energy ones, if it was not cut short).
  @spec problems(pid(), [Dolphin.Check.Mission.problem()], pos_integer() | nil) :: :ok
  def problems(recorder, problems, line), do: GenServer.call(recorder, {:problems, problems, line})

  # Where a flight left its vehicle, and whether in the air.
  @spec ended(pid(), non_neg_integer(), Dolphin.Geo.Location.t() | nil, boolean()) :: :ok
  def ended(recorder, vehicle, at, airborne?), do: GenServer.cast(recorder, {:ended, vehicle, at, airborne?})

  # {findings, estimates}, in the order the missions started.
  @spec results(pid()) :: {[Finding.t()], [map()]}
  def results(recorder), do: GenServer.call(recorder, :results)

  @impl true
  def init(args) do
    # args: test (the FakeSource name), file, limits, vehicles (id => %{payloads, home, airborne?})
    {:ok, Map.merge(args, %{findings: [], estimates: []})}
  end

  @impl true
  def handle_call({:mission, mission, id, line}, _from, s) do
    fleet = Map.get(s.vehicles, id, %{payloads: [], home: nil, airborne?: false})
    battery = case FakeSource.vehicle(s.test, id), do: ({:ok, view} -> view.battery; _ -> nil)
    vehicle = %{id: id, payloads: fleet.payloads, battery: battery, position: fleet.home, airborne?: fleet.airborne?, at: Map.get(fleet, :at), airframe: Map.get(fleet, :airframe)}
    {problems, energy, estimate} = Dolphin.Check.Mission.check(mission, vehicle, s.limits)
    estimate = estimate && Map.merge(estimate, %{line: line, energy: energy})
    # What the report keeps of an estimate (the flight needs the rest).
    estimates = if estimate, do: [Map.take(estimate, [:mission, :vehicle, :line, :length_m, :time_s, :battery_used, :battery_start, :ending]) | s.estimates], else: s.estimates
    {:reply, estimate, %{s | findings: Enum.reverse(findings(problems, s.file, line)) ++ s.findings, estimates: estimates}}
  end

  def handle_call({:problems, problems, line}, _from, s),
    do: {:reply, :ok, %{s | findings: Enum.reverse(findings(problems, s.file, line)) ++ s.findings}}

  def handle_call(:results, _from, s), do: {:reply, {Enum.reverse(s.findings), Enum.reverse(s.estimates)}, s}

  defp findings(problems, file, line),
    do: for({severity, kind, message} <- problems, do: %Finding{severity: severity, kind: kind, file: file, line: line, message: message})

  @impl true
  def handle_cast({:ended, id, at, airborne?}, s) do
    vehicles = Map.update(s.vehicles, id, %{payloads: [], home: nil, airborne?: airborne?, at: at}, &Map.merge(&1, %{airborne?: airborne?, at: at}))
    {:noreply, %{s | vehicles: vehicles}}
  end
end
