defmodule Dolphin.Sim.CopterPropertyTest do
  # Random missions flown by the pure copter model: every item is reached, in
  # order, each waypoint within its acceptance radius, and the flight ends
  # landed and disarmed at home.
  use ExUnit.Case, async: true

  import Dolphin.Property

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.Copter

  @home %{lat: 40.444233, lon: -7.375234, alt: 820.0}
  @gcs {255, 190}
  @step 50

  # A mission: take off, then waypoints (north, east, height above home, hold
  # seconds), some of them loiters of a few turns, then RTL.
  defp mission_gen do
    leg = :proper_types.tuple([:proper_types.integer(-300, 300), :proper_types.integer(-300, 300), :proper_types.integer(10, 60), :proper_types.integer(0, 3), :proper_types.elements([:wp, :wp, :turns])])
    :proper_types.tuple([:proper_types.integer(10, 40), :proper_types.non_empty(:proper_types.resize(5, :proper_types.list(leg)))])
  end

  defp items({take_off, legs}) do
    point = fn n, e -> Copter.offset(@home, n * 1.0, e * 1.0) end

    legs_items =
      legs
      |> Enum.with_index(2)
      |> Enum.map(fn {{n, e, up, hold, kind}, seq} ->
        p = point.(n, e)
        {command, params} = if kind == :turns, do: {18, %{param1: 1.0, param3: 15.0}}, else: {16, %{param1: hold * 1.0}}
        item(seq, command, p, up, params)
      end)

    [item(0, 16, @home, 0), item(1, 22, @home, take_off)] ++ legs_items ++ [item(length(legs) + 2, 20, %{lat: 0.0, lon: 0.0}, 0)]
  end

  defp item(seq, command, %{lat: lat, lon: lon}, up, params \\ %{}) do
    struct(M.MissionItemInt, Map.merge(%{seq: seq, command: command, frame: 6, x: round(lat * 1.0e7), y: round(lon * 1.0e7), z: up * 1.0, autocontinue: 1}, params))
  end

  defp tell(c, message), do: c |> Copter.handle(message, @gcs) |> Copter.flush() |> elem(1)

  defp command(c, command, params) do
    [p1, p2 | _] = params ++ [0, 0]
    tell(c, %M.CommandLong{target_system: 1, target_component: 1, command: command, param1: p1 * 1.0, param2: p2 * 1.0})
  end

  # Steps until landed and disarmed after the mission (at most `max_ms`), collecting
  # where the vehicle was at each MISSION_ITEM_REACHED.
  defp fly(c, max_ms, reached) do
    {out, c} = c |> Copter.step(@step) |> Copter.flush()
    reached = reached ++ for({_, %M.MissionItemReached{seq: seq}} <- out, do: {seq, {c.n, c.e, c.alt}})

    cond do
      c.mission_state == 5 and not c.armed -> {c, reached}
      max_ms <= 0 -> {c, reached}
      true -> fly(c, max_ms - @step, reached)
    end
  end

  test "random missions: every item reached in order, at its point, then landed at home" do
    check(
      forall(mission_gen(), fn mission ->
        items = items(mission)
        {c, _} = Enum.reduce(1..100, {Copter.new(1, @home, %{ekf_ready_ms: 1_000}), nil}, fn _, {c, _} -> {Copter.step(c, @step), nil} end)
        c = tell(c, %M.MissionCount{target_system: 1, target_component: 1, count: length(items), mission_type: 0})
        c = Enum.reduce(items, c, &tell(&2, &1))
        assert length(Dolphin.Sim.MissionServer.items(c.missions)) == length(items) - 1

        c = c |> command(176, [1, 4]) |> command(400, [1]) |> command(300, [0, 0])
        {c, reached} = fly(c, 3_600_000, [])

        assert Enum.map(reached, &elem(&1, 0)) == Enum.to_list(1..(length(items) - 1))

        # Each waypoint reached within its acceptance radius (2 m), at its height.
        for {seq, {n, e, alt}} <- reached, item = Enum.at(items, seq), item.command == 16 do
          {tn, te} = Copter.ne(c, item.x / 1.0e7, item.y / 1.0e7)
          assert :math.sqrt((n - tn) ** 2 + (e - te) ** 2 + (alt - (@home.alt + item.z)) ** 2) <= 2.0
        end

        assert c.landed == :on_ground and not c.armed
        assert :math.sqrt(c.n * c.n + c.e * c.e) < 2.5
        true
      end),
      numtests: 30
    )
  end
end
