defmodule Dolphin.Mission.Platform do
  @moduledoc """
  The MAVLink platform of the engine (`Dolphin.Engine.Platform`): a
  `%Dolphin.Mission{}` is a task that flies one vehicle.

      survey = mission "Survey" do ... end
      execute(until(survey, battery(v) < 0.3) >>> return_home)

  Running one starts a process (one per running mission) that, as ArduCopter
  needs it:

    1. holds the vehicle first if it is flying another mission;
    2. clears the vehicle's mission, uploads this one (`Dolphin.Mission.to_items/1`;
       a mission without `home` gets the vehicle's home as item 0) and emits
       `mission_uploaded` (items, duration, retransmissions);
    3. downloads it back and compares it by meaning
       (`Dolphin.Mission.compare_download/2`) — a mission is never started unverified;
    4. switches to GUIDED and arms, retrying while the autopilot refuses (it is
       not ready for ~a minute after boot) for at most 120 s of clock time, then
       fails with the autopilot's STATUSTEXT reason;
    5. sends MISSION_START right after arming (the vehicle disarms itself
       ~10 s after arming on the ground) and follows the flight, reporting
       progress (`%{reached, current, total}`) as `task_progress` events.

  It completes when the last item is reached or, for a mission that ends in a
  landing, when the vehicle has landed and disarmed; a mission that ends in an
  endless loiter (or loops for ever) runs until it is stopped. It fails with a
  reason that says what and where (upload rejected, verification mismatch,
  arming refused, a mode change refused, the vehicle leaving AUTO — a battery
  failsafe, say — or disarming before the end, the vehicle lost).

  Stopped (by `until`, `during`, `one_of`, a failed sibling, the operator), it
  leaves the vehicle holding position — BRAKE, else GUIDED; never LOITER, which
  is pilot-controlled on ArduCopter and sinks without RC input — or disarmed
  if it had not left the ground, and the vehicle is free for the next task.

  Requirements: a mission that takes off needs a `:uav`; one that takes photos
  needs a vehicle with the `:camera` payload.

  Taken over by another vehicle (`reassign`), a mission goes on where its
  first vehicle left it (`Dolphin.Mission.Resume`): the vehicle lost, a
  failsafe taking it out of AUTO, a refused arm count as the vehicle's
  failures. A lost vehicle heard again after its mission was taken over is
  made to hold (a vehicle that was only out of range still flies it) and a
  `vehicle_returned` event says so.

  Who flies a mission is the run's choice, through its context's
  `platform_opts` (`Dolphin.Engine.Context`): by default the MAVLink
  executor above; with `missions: {module, arg}`, `module.fly(arg, mission,
  vehicle, opts)` stands in for it (`{:ok, pid}` of a process that reports
  to the engine as the executor does, or `{:error, reason}`): the pre-flight
  check's dry run estimates the mission and passes its time
  (`Dolphin.Check.Source`), a run on fake vehicles refuses it
  (`refusing/1`).
  """

  @behaviour Dolphin.Engine.Platform

  alias Dolphin.{Mission, PubSub, Events, Vehicles}
  alias Dolphin.Mission.{Executor, Resume}

  defimpl Dolphin.Engine.Taskable, for: Dolphin.Mission do
    def to_task(mission), do: Dolphin.Engine.platform_task(Dolphin.Mission.Platform, mission)
  end

  @camera_commands [:capture_photo, :capture_several_photos, :capture_until_stop, :stop_capturing]

  @impl true
  def name(%Mission{name: name}), do: name

  @impl true
  def kind(_mission), do: :mission

  @impl true
  # The airframes that can fly every command of the mission
  # (`Dolphin.Mission.airframes/1`): a mission of raw items only (`item`)
  # may go to a vehicle of any airframe, even an unknown one.
  def requirements(%Mission{commands: commands} = mission) do
    kinds = Enum.map(commands, & &1.kind)
    payloads = if Enum.any?(kinds, &(&1 in @camera_commands)), do: [:camera], else: []
    %{airframe: Mission.airframes(mission), payloads: payloads}
  end

  @impl true
  def start(%Mission{} = mission, vehicle, opts) do
    case opts[:missions] do
      {module, arg} -> module.fly(arg, mission, vehicle, opts)
      nil -> Executor.start_link(mission, vehicle, opts)
    end
  end

  @doc """
  The `platform_opts` of a run whose missions cannot fly (on fake
  vehicles, `--fake`): each fails at once with a `Dolphin.Mission.Failure`
  of that `cause`.
  """
  @spec refusing(Dolphin.Mission.Failure.cause()) :: keyword()
  def refusing(cause), do: [missions: {__MODULE__, {:refuse, cause}}]

  @doc false
  # The missions of a run that `refusing/1` set up.
  def fly({:refuse, cause}, %Mission{} = mission, vehicle, _opts),
    do: {:error, %Dolphin.Mission.Failure{mission: mission.name, vehicle: vehicle, step: :hold, cause: cause}}

  @impl true
  def vehicle_fault?({:vehicle_lost, _}), do: true
  def vehicle_fault?(%Dolphin.Mission.Failure{vehicle_fault?: fault?}), do: fault?
  def vehicle_fault?(_reason), do: false

  @impl true
  def resume(%Mission{} = mission, progress, from, to) do
    # The items the first vehicle flew were made with its home (when the mission has none).
    with {:ok, mission} <- with_home(mission, from),
         {:ok, at} <- standing(mission, to) do
      Resume.resume(mission, progress && progress[:reached], at)
    end
  end

  @impl true
  def abandoned(vehicle, opts) do
    owner = Keyword.fetch!(opts, :owner)
    me = self()
    # Not linked to the task: it outlives the task that gave the mission
    # away, until the script ends; supervised under Dolphin.Mission.Guards.
    {:ok, pid} = Task.Supervisor.start_child(Dolphin.Mission.Guards, fn -> guard(vehicle, owner, opts, me) end)
    receive do: ({:"$dolphin_guarding", ^pid} -> :ok)
  end

  defp with_home(%Mission{home: %Dolphin.Geo.Location{}} = mission, _from), do: {:ok, mission}

  defp with_home(mission, from) do
    case Vehicles.view(from) do
      {:ok, %{home: %Dolphin.Geo.Location{} = home}} -> {:ok, Mission.put_home(mission, home)}
      _ -> {:error, %Dolphin.Mission.Failure{mission: mission.name, vehicle: from, step: :resume, cause: {:home_unknown, from}}}
    end
  end

  defp standing(mission, vehicle) do
    case Vehicles.view(vehicle) do
      {:ok, %{position: %Dolphin.Geo.Location{} = at}} -> {:ok, at}
      _ -> {:error, %Dolphin.Mission.Failure{mission: mission.name, vehicle: vehicle, step: :resume, cause: {:position_unknown, vehicle}}}
    end
  end

  # Waits for the vehicle to be heard again (as long as the script runs), then holds it.
  defp guard(vehicle, owner, opts, caller) do
    ref = Process.monitor(owner)
    PubSub.subscribe(:vehicles)
    send(caller, {:"$dolphin_guarding", self()})
    await_return(vehicle, ref, opts)
  end

  defp await_return(vehicle, ref, opts) do
    receive do
      {:dolphin, :vehicles, {:vehicle_reconnected, ^vehicle}} ->
        held = Dolphin.Vehicles.Manoeuvres.hold(vehicle) == :ok
        Events.emit(:vehicle_returned, %{run: opts[:run], task_id: opts[:task_id], vehicle: vehicle, held: held})

      {:DOWN, ^ref, :process, _, _} ->
        :ok

      # The other vehicles' news.
      _other ->
        await_return(vehicle, ref, opts)
    end
  end

  @impl true
  def stop(pid, reason) do
    Executor.stop(pid, reason)
  catch
    # Already over (it finished or failed as it was being stopped).
    :exit, _ -> :ok
  end

  @impl true
  def stop_request(reason), do: Executor.stop_request(reason)
end
