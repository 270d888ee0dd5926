defmodule Dolphin.AirframeTest do
  use ExUnit.Case, async: true

  alias Dolphin.Airframe
  alias Dolphin.Sim.Copter

  doctest Dolphin.Airframe
  doctest Dolphin.Vehicles.Manoeuvres, only: [hold_modes: 1]

  test "every airframe a heartbeat names has its module, and each module implements the whole behaviour" do
    callbacks = Airframe.behaviour_info(:callbacks)

    for airframe <- Dolphin.Vehicles.View.airframes() do
      module = Airframe.of(airframe)
      assert Airframe in Keyword.get(module.module_info(:attributes), :behaviour, []), "#{inspect(module)} is no Dolphin.Airframe"
      for {name, arity} <- callbacks, do: assert(function_exported?(module, name, arity), "#{inspect(module)}.#{name}/#{arity}")
      assert module.firmware() =~ ~r/^Ardu/
    end
  end

  test "the simulator moves and draws as the check estimates: one set of figures" do
    for airframe <- Dolphin.Sim.airframes() do
      c = Copter.new(1, %{lat: 38.4, lon: -8.8, alt: 0.0}, %{airframe: airframe})
      p = Airframe.performance(airframe)

      for key <- [:cruise_speed, :climb_speed, :descent_speed, :accel, :circle_speed, :wp_radius, :hover_current, :capacity_mah],
          do: assert(Map.fetch!(c.config, key) == Map.fetch!(p, key), "#{airframe} #{key}")

      # Armed and moving north at cruise, climbing 1 m/s (in the air for what flies).
      moving = %{c | armed: true, landed: :in_air, alt: 50.0, vn: p.cruise_speed, vz: 1.0}
      stepped = Copter.Battery.step(moving, 1.0)
      assert_in_delta stepped.current_a, Airframe.current(airframe, p.cruise_speed, 1.0, true), 1.0e-9, "#{airframe}"
    end
  end

  test "what the language refuses follows from the airframes: take-offs for what takes off, landings for what lands" do
    alias Dolphin.Mission.Command, as: C
    up = Dolphin.Mission.new("up", [C.take_off(41.0, -8.0, 120)])
    down = Dolphin.Mission.new("down", [C.return_home_and_land()])
    assert Dolphin.Mission.airframes(up) == for(a <- Dolphin.Vehicles.View.airframes(), Airframe.of(a).takes_off?(), do: a)
    assert Dolphin.Mission.airframes(down) == for(a <- Dolphin.Vehicles.View.airframes(), Airframe.of(a).lands?(), do: a)
    assert Dolphin.Mission.airframes(down) -- Dolphin.Mission.airframes(up) == [:sub]
  end

  test "a plane's turn radius grows with the square of its speed; its loiters are flown no tighter than it can" do
    assert_in_delta Airframe.turn_radius(:plane, 22.0), 22.0 * 22.0 / 9.81, 1.0e-9
    assert_in_delta Airframe.turn_radius(:plane, 11.0) * 4, Airframe.turn_radius(:plane, 22.0), 1.0e-9
    assert Airframe.turn_radius(:copter, 20.0) == 0.0
    assert Airframe.flown_radius(:plane, 20) == 60.0
    assert Airframe.flown_radius(:plane, -100) == -120.0
    assert Airframe.flown_radius(:plane, 0) == 96.0
    assert Airframe.flown_radius(:sub, 20) == 20.0
  end
end
