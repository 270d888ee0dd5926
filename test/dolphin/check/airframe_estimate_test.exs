defmodule Dolphin.Check.AirframeEstimateTest do
  # The pre-flight check's energy and time, airframe by airframe, against the
  # simulator flying the same items (the pure model, no sockets): both take
  # their figures from Dolphin.Airframe, and the simulator is held to each
  # firmware's SITL by the differential tests (test/dolphin/sitl/airframes_test.exs).
  use ExUnit.Case, async: true

  alias Dolphin.Check.Mission, as: Check
  alias Dolphin.Mission
  alias Dolphin.Mission.Command, as: C
  alias Dolphin.Sim.Copter
  alias Dolphin.Test.SimModel

  @origin %{lat: 38.43462, lon: -8.86118, alt: 0.0}
  @home Dolphin.Geo.location(38.43462, -8.86118, 0.0)
  @step 100
  @limits %{max_distance: 5_000, max_height: 500}

  defp missions do
    [
      copter: [C.take_off(Dolphin.Geo.Location.at_height(@home, 30)), C.move(600, 0, 0), C.move_and_loiter_turns(0, 300, 0, 2, 40), C.return_home_and_land()],
      plane: [C.take_off(Dolphin.Geo.Location.at_height(@home, 80), 12), C.move(1500, 0, 0), C.move_and_loiter_turns(0, 1200, 0, 1, 150), C.landing_point(@home)],
      rover: [C.move(300, 0, 0), C.move_and_loiter_time(0, 200, 0, 20, 0), C.move(-300, -200, 0)],
      boat: [C.move(250, 250, 0), C.move(-250, 0, 0)],
      sub: [C.move(0, 0, -8), C.move(120, 0, 0), C.move(0, 60, -4), C.landing_point(Dolphin.Geo.offset(@home, 120, 60, 0))]
    ]
  end

  for {airframe, _} <- [copter: 0, plane: 0, rover: 0, boat: 0, sub: 0] do
    test "a #{airframe}'s time and battery use, estimated, are what the simulator's #{airframe} takes" do
      airframe = unquote(airframe)
      mission = Mission.new("#{airframe}", [C.home(@home) | missions()[airframe]])
      items = Mission.to_items(mission, airframe: airframe)
      vehicle = %{id: 1, airframe: airframe, payloads: [], battery: 1.0, position: @home, airborne?: false}

      assert {problems, [], estimate} = Check.check(mission, vehicle, @limits)
      refute Enum.any?(problems, &(elem(&1, 0) == :error)), inspect(problems)

      {seconds, used} = fly(airframe, items, Mission.ending(items, airframe))
      # Within a quarter: the estimate flies straight legs at cruise; the
      # simulator accelerates, rounds corners and circles on to its track.
      assert_in_delta estimate.time_s, seconds, 0.25 * seconds, "#{airframe}: estimated #{round(estimate.time_s)} s, flown #{round(seconds)} s"
      assert_in_delta estimate.battery_used, used, 0.25 * used, "#{airframe}: estimated #{Float.round(estimate.battery_used * 100, 1)} %, used #{Float.round(used * 100, 1)} %"
    end
  end

  # Flies `items` in the simulator from the arming to the mission's end:
  # landed and disarmed, or its last item reached; the clock time and the
  # pack's fraction used.
  defp fly(airframe, items, ending) do
    c = Copter.new(1, @origin, %{airframe: airframe, ekf_ready_ms: 2_000}) |> steps(3_000) |> SimModel.upload(items)
    type = Copter.mav_type(c)
    c = c |> mode(type, :guided) |> command(400, [1]) |> command(300, [0, 0])
    armed_at = c.time_ms

    done? =
      case ending do
        {:landing, _} -> fn c -> not c.armed end
        {:reached, _} -> fn c -> c.mission_state == 5 end
      end

    c = until(c, done?, 3_600_000)
    {(c.time_ms - armed_at) / 1000, 1.0 - c.battery}
  end

  defp steps(c, ms), do: Enum.reduce(1..div(ms, @step), c, fn _, c -> c |> Copter.step(@step) |> Copter.flush() |> elem(1) end)

  defp until(c, done?, left_ms) do
    cond do
      done?.(c) -> c
      left_ms <= 0 -> flunk("the mission did not end: mode #{c.mode}, item #{c.current}, armed #{c.armed}, alt #{c.alt}, nav #{inspect(c.nav)}")
      true -> c |> steps(@step) |> until(done?, left_ms - @step)
    end
  end

  defp mode(c, type, name) do
    {:ok, number} = Dolphin.Vehicles.Modes.number(:ardupilot, type, name)
    command(c, 176, [1, number])
  end

  defp command(c, command, params) do
    {c, result, texts} = SimModel.command(c, command, params)
    assert result == 0, "command #{command} refused: #{inspect(texts)}"
    c
  end
end
