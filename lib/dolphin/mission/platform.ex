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
  """

  @behaviour Dolphin.Engine.Platform

  alias Dolphin.Mission
  alias Dolphin.Mission.Executor

  defimpl Dolphin.Engine.Taskable, for: Dolphin.Mission do
    def to_task(mission), do: Dolphin.Engine.platform_task(Dolphin.Mission.Platform, mission)
  end

  @camera_commands [:capture_photo, :capture_several_photos, :capture_until_stop, :stop_capturing]

  @impl true
  def name(%Mission{name: name}), do: name

  @impl true
  def kind(_mission), do: :mission

  @impl true
  def requirements(%Mission{commands: commands}) do
    kinds = Enum.map(commands, & &1.kind)
    type = if Enum.any?(kinds, &(&1 in [:take_off, :take_off_with_yaw])), do: :uav, else: nil
    payloads = if Enum.any?(kinds, &(&1 in @camera_commands)), do: [:camera], else: []
    %{type: type, payloads: payloads}
  end

  @impl true
  def start(%Mission{} = mission, vehicle, opts) do
    case opts[:source] do
      # A source of stand-in vehicles (the pre-flight check's dry run,
      # `Dolphin.Check`) flies missions itself: nothing is sent to a vehicle.
      {module, arg} when is_atom(module) ->
        if function_exported?(module, :start_mission, 4),
          do: module.start_mission(arg, mission, vehicle, opts),
          else: Executor.start_link(mission, vehicle, opts)

      _ ->
        Executor.start_link(mission, vehicle, opts)
    end
  end

  @impl true
  def stop(pid, reason) do
    Executor.stop(pid, reason)
  catch
    # Already over (it finished or failed as it was being stopped).
    :exit, _ -> :ok
  end
end
