defmodule Dolphin.Mission.FailureTest do
  use ExUnit.Case, async: true
  doctest Dolphin.Mission.Failure

  alias Dolphin.Mission.Failure

  test "a failure quotes the autopilot's first warning about it" do
    f = %Failure{mission: "Survey", vehicle: 3, step: :flying, cause: :disarmed, status_texts: [{6, "Arming motors"}, {2, "Crash: Disarming"}], vehicle_fault?: true}
    assert Exception.message(f) == ~s(the vehicle disarmed before the mission ended: the autopilot says "Crash: Disarming")
  end

  test "the engine words a mission's failure as the failure says, and reassign reads whether the vehicle caused it" do
    refused = %Failure{mission: "Survey", vehicle: 3, step: :arm, cause: {:refused, %Dolphin.CommandError{command: :arm, vehicle: 3, result: :failed, attempts: 1, detail: "PreArm: Need Position Estimate"}}, vehicle_fault?: true}
    assert Dolphin.Engine.Failure.format_reason(refused) == Exception.message(refused)
    assert Dolphin.Mission.Platform.vehicle_fault?(refused)
    refute Dolphin.Mission.Platform.vehicle_fault?(%{refused | vehicle_fault?: false})
  end
end
