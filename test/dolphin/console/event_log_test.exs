defmodule Dolphin.Console.EventLogTest do
  use ExUnit.Case, async: true

  alias Dolphin.Console.EventLog

  test "the store keeps the last events, oldest first, and filters them" do
    name = :"events_#{System.unique_integer([:positive])}"
    pid = start_supervised!(%{id: name, start: {EventLog, :start_link, [[name: name, max: 3, subscribe: false]]}})

    for i <- 1..5, do: send(pid, {:dolphin, :events, %{event: :message, text: "#{i}", at_ms: i}})
    send(pid, {:dolphin, :events, %{event: :armed, vehicle: 1, at_ms: 6}})

    assert Enum.map(EventLog.last(10, fn _ -> true end, name), &Map.get(&1, :text)) == ["4", "5", nil]
    assert Enum.map(EventLog.last(1, &(&1.event == :message), name), & &1.text) == ["5"]
    assert EventLog.last(2, fn e -> e.no_such_field end, name) == []
    assert is_integer(EventLog.origin_ms(name))
  end

  test "task states follow a task's events and are forgotten when it finishes" do
    states =
      [
        %{event: :task_started, task_id: 4, kind: :mission, vehicle: 1},
        %{event: :task_started, task_id: 5, kind: :wait_for, vehicle: nil},
        %{event: :task_progress, task_id: 4, vehicle: 1, progress: %{current: 1, total: 3, reached: nil}},
        %{event: :condition_met, task_id: 5, branch: nil, condition: "x"},
        %{event: :armed, vehicle: 1},
        %{event: :task_finished, task_id: 5, result: :done}
      ]
      |> Enum.reduce(%{}, &EventLog.track(&2, &1))

    assert states == %{4 => "item 1/3"}
  end

  test "the application's store is running" do
    assert is_pid(Process.whereis(Dolphin.Console.EventLog))
    assert is_list(EventLog.last(5))
  end
end
