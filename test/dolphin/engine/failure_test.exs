defmodule Dolphin.Engine.FailureTest do
  use ExUnit.Case, async: true

  alias Dolphin.Engine.Failure

  doctest Dolphin.Engine.Failure

  test "the stop reasons the engine, a script and a run give read as words, not terms" do
    reasons = [
      :stopped,
      :halted,
      :operator,
      :shutdown,
      :deadline,
      {:signal, :sigint},
      {:signal, :sigterm},
      {:parent_exit, :normal},
      {:parent_exit, :killed},
      {:parent_exit, :shutdown},
      {:crashed, :killed},
      {:crashed, :start_timeout},
      {:crashed, :no_report_after_stop},
      {:platform_exited, :normal},
      {:stop_failed, {:exit, :killed}},
      {:exit, :shutdown}
    ]

    for reason <- reasons do
      text = Failure.format_reason(reason)
      refute text =~ ~r/[:{}]\w|\(:/, "#{inspect(reason)} reads #{inspect(text)}"
    end

    assert Failure.format_reason({:parent_exit, :killed}) == "stopped: what started it was stopped"
    assert Failure.format_reason(:stopped) == "stopped: the task above it ended"
  end

  test "a stop that failed carries the manoeuvre's error as data, worded where it is shown" do
    refusal = %Dolphin.CommandError{command: :mav_cmd_do_set_mode, vehicle: 2, result: :denied, attempts: 1}
    hold = %Dolphin.ManoeuvreError{manoeuvre: :hold, vehicle: 2, action: "hold", refusal: refusal}

    assert Failure.format_reason({:stop_failed, hold}) ==
             "could not be stopped: the vehicle could not be made to hold position: vehicle 2 refused MAV_CMD_DO_SET_MODE: MAV_RESULT_DENIED"
  end

  test "an unforeseen reason is shown as it is" do
    assert Failure.format_reason({:weird, 1}) == "{:weird, 1}"
    assert Failure.format_reason({:crashed, {:badarg, []}}) == "engine process crashed ({:badarg, []})"
  end
end
