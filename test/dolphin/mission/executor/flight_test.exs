defmodule Dolphin.Mission.Executor.FlightTest do
  # The judgement of a mission in flight, from vehicle states alone.
  use ExUnit.Case, async: true

  alias Dolphin.Mission.Executor.Flight

  # A view of the vehicle (`armed` for its `armed?`).
  defp st(fields) do
    mission = Map.merge(%{state: nil, current: nil, reached: nil, total: 3}, Map.get(fields, :mission, %{}))
    {armed, fields} = Map.pop(fields, :armed, false)
    struct!(Dolphin.Vehicles.View, Map.merge(%{mode: :guided, landed: :on_ground}, fields) |> Map.merge(%{mission: mission, armed?: armed}))
  end

  defp run(flight, states), do: Enum.map_reduce(states, flight, fn s, f ->
      {v, p, f} = Flight.judge(f, s)
      {{v, p}, f}
    end)

  test "the previous mission's state is no progress: nothing counts before this mission is active" do
    {[{verdict, progress}], flight} = run(Flight.new({:reached, 3}), [st(%{mode: :auto, armed: false, mission: %{state: :complete}})])
    assert {verdict, progress} == {:flying, nil}
    refute flight.active
  end

  test "a mission ending on an item reached is done when the vehicle reports it complete" do
    states = [
      st(%{mode: :auto, armed: true, landed: :in_air, mission: %{state: :active, current: 1}}),
      st(%{mode: :auto, armed: true, landed: :in_air, mission: %{state: :active, current: 2, reached: 1}}),
      st(%{mode: :auto, armed: true, landed: :in_air, mission: %{state: :complete, current: 3, reached: 3}})
    ]

    {verdicts, _} = run(Flight.new({:reached, 3}), states)
    assert Enum.map(verdicts, &elem(&1, 0)) == [:flying, :flying, :done]
    assert [%{current: 1, reached: nil}, %{current: 2, reached: 1}, %{current: 3, reached: 3}] = Enum.map(verdicts, &elem(&1, 1))
  end

  test "ArduCopter's landing end: flew the land item armed, then disarmed on the ground with the mission reset to item 1" do
    states = [
      st(%{mode: :auto, armed: true, landed: :in_air, mission: %{state: :active, current: 2, total: 3}}),
      st(%{mode: :auto, armed: true, landed: :landing, mission: %{state: :active, current: 3, reached: 2, total: 3}}),
      # The reset to item 1 comes before the heartbeat shows the disarm: no progress.
      st(%{mode: :auto, armed: true, landed: :landing, mission: %{state: :active, current: 1, reached: 2, total: 3}}),
      st(%{mode: :auto, armed: false, landed: :on_ground, mission: %{state: :active, current: 1, reached: 2, total: 3}})
    ]

    {verdicts, _} = run(Flight.new({:landing, 3}), states)
    assert Enum.map(verdicts, &elem(&1, 0)) == [:flying, :flying, :flying, :done]
    assert Enum.at(verdicts, 2) == {:flying, nil}
  end

  test "a landing mission's vehicle disarmed before its land item: its reports are waited for, then it failed" do
    states = [
      st(%{mode: :auto, armed: true, landed: :in_air, mission: %{state: :active, current: 2, total: 3}}),
      st(%{mode: :auto, armed: false, landed: :on_ground, mission: %{state: :active, current: 2, reached: 1, total: 3}})
    ]

    {verdicts, flight} = run(Flight.new({:landing, 3}), states)
    assert Enum.map(verdicts, &elem(&1, 0)) == [:flying, :check_landed]
    # Asked once only.
    assert {:flying, nil, _} = Flight.judge(flight, List.last(states))
    assert {:failed, {:landed_early, 2, 3} = cause} = Flight.landed(flight, List.last(states))
    assert Exception.message(%Dolphin.Mission.Failure{cause: cause}) == "the vehicle landed and disarmed before the mission's end (at item 2 of 3)"
    assert :done = Flight.landed(flight, st(%{mode: :auto, armed: false, mission: %{state: :complete, current: 3, total: 3}}))
  end

  test "leaving AUTO or disarming counts only once the heartbeat showed AUTO, or armed, during this mission" do
    # ACTIVE reported before the heartbeat shows AUTO and armed: not a departure.
    early = Flight.reported(Flight.new({:reached, 3}), st(%{mode: :guided, mission: %{state: :active}}))
    assert {:flying, _, _} = Flight.judge(early, st(%{mode: :guided, armed: false, mission: %{state: :active, current: 1}}))

    flying = st(%{mode: :auto, armed: true, landed: :in_air, mission: %{state: :active, current: 1}})
    {:flying, _, flight} = Flight.judge(Flight.new({:reached, 3}), flying)
    assert {{:left, {:left_auto, "RTL"}}, _, _} = Flight.judge(flight, %{flying | mode: :rtl})
    assert {{:left, {:left_auto, "mode 99"} = cause}, _, _} = Flight.judge(flight, %{flying | mode: {:custom, 99}})
    assert Exception.message(%Dolphin.Mission.Failure{cause: cause}) == "the vehicle left AUTO for mode 99 before the mission ended"
    assert {{:left, :disarmed}, _, _} = Flight.judge(flight, %{flying | armed?: false})
  end

  test "MISSION_CURRENT's ACTIVE in a view counts, before the heartbeat shows AUTO and after a later view no longer shows it" do
    flight = Flight.reported(Flight.new({:reached, 3}), st(%{mode: :guided, mission: %{state: :active}}))
    assert {:done, _, _} = Flight.judge(flight, st(%{mode: :auto, armed: true, mission: %{state: :complete, current: 3}}))
    assert {:flying, nil, _} = Flight.judge(Flight.new({:reached, 3}), st(%{mode: :guided, armed: true, mission: %{state: :complete, current: 3}}))
  end

  test "a mission that never ends (an endless loiter) is never done" do
    s = st(%{mode: :auto, armed: true, landed: :in_air, mission: %{state: :complete, current: 2, reached: 2}})
    assert {:flying, _, _} = Flight.judge(Flight.new(:forever), s)
  end

  test "what was seen before the judging began counts: a short landing mission flown while MISSION_START's answer was awaited" do
    flight =
      Enum.reduce(
        [
          st(%{mode: :auto, armed: true, landed: :in_air, mission: %{state: :active, current: 1, total: 2}}),
          st(%{mode: :auto, armed: true, landed: :landing, mission: %{state: :active, current: 2, reached: 1, total: 2}})
        ],
        Flight.new({:landing, 2}),
        &Flight.observe(&2, &1)
      )

    # Judged first once landed, disarmed, the mission reset to item 1.
    landed = st(%{mode: :auto, armed: false, landed: :on_ground, mission: %{state: :active, current: 1, reached: 1, total: 2}})
    assert {:done, _, _} = Flight.judge(flight, landed)
    # Seen armed only before its land item: landed short of the mission's end.
    early = Flight.observe(Flight.new({:landing, 2}), st(%{mode: :auto, armed: true, landed: :in_air, mission: %{state: :active, current: 1, total: 2}}))
    assert {:check_landed, _, early} = Flight.judge(early, landed)
    assert {:failed, _} = Flight.landed(early, landed)
  end
end
