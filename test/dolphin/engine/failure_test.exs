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

  test "an unforeseen reason is shown as it is" do
    assert Failure.format_reason({:weird, 1}) == "{:weird, 1}"
    assert Failure.format_reason({:crashed, {:badarg, []}}) == "engine process crashed ({:badarg, []})"
  end
end
