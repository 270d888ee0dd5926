defmodule Dolphin.Sim.Copter.BatteryTest do
  # The simulated battery: drain, charge, warnings and failsafe, on the model's state directly.
  use ExUnit.Case, async: true

  alias Dolphin.Sim.Copter
  alias Dolphin.Sim.Copter.Battery

  @home %{lat: 40.444233, lon: -7.375234, alt: 820.0}

  defp ready(config \\ %{}), do: Copter.new(1, @home, Map.merge(%{ekf_ready_ms: 0}, config)) |> Copter.step(50) |> Copter.flush() |> elem(1)
  defp in_air(c, fields \\ %{}), do: struct(c, Map.merge(%{mode: :guided, armed: true, landed: :in_air, alt: @home.alt + 20, nav: {:hold, 0.0, 0.0, @home.alt + 20}}, fields))
  defp texts(c), do: for({_, %{text: t}} <- Enum.reverse(c.out), do: t)

  test "drains while armed, more in the air and more when climbing and flying fast" do
    c = ready()
    on_ground = Battery.step(%{c | armed: true}, 1.0)
    hovering = Battery.step(in_air(c), 1.0)
    climbing = Battery.step(in_air(c, %{vn: 10.0, vz: 2.5}), 1.0)

    assert on_ground.current_a == 0.15 * c.config.hover_current
    assert hovering.current_a == c.config.hover_current
    assert_in_delta climbing.current_a, 1.3 * c.config.hover_current, 1.0e-9
    assert on_ground.battery > hovering.battery and hovering.battery > climbing.battery
    assert_in_delta hovering.consumed_mah, c.config.hover_current / 3.6, 1.0e-9
    assert_in_delta hovering.battery, 1.0 - c.config.hover_current / 3.6 / c.config.capacity_mah, 1.0e-12

    # Disarmed: no current, no drain.
    idle = Battery.step(%{c | battery: 0.5}, 1.0)
    assert idle.current_a == 0.0
  end

  test "charges disarmed on the ground at home or at the charger, not elsewhere" do
    c = %{ready() | battery: 0.5, consumed_mah: 1650.0}
    charged = Battery.step(c, 10.0)
    assert_in_delta charged.battery, 0.5 + 10 * c.config.charge_rate, 1.0e-12
    assert charged.consumed_mah < c.consumed_mah

    away = %{c | n: 200.0}
    assert Battery.step(away, 10.0).battery == 0.5
    refute Battery.at_home?(away)

    charger = Copter.offset(@home, 200, 0)
    assert Battery.at_home?(%{away | config: %{c.config | charger: charger}})
    refute Battery.at_home?(%{c | landed: :in_air})
    assert Battery.step(%{c | battery: 0.999}, 10.0).battery == 1.0
  end

  test "warns once when low and when critical, and blocks arming" do
    c = in_air(ready(), %{battery: 0.2005})
    c = Battery.step(c, 1.0)
    assert c.battery_warned == :low and c.arm_blocked
    assert [<<"Battery 1 is low ", _::binary>>] = texts(c)
    # No failsafe configured: it flies on in GUIDED.
    assert c.mode == :guided

    c = c |> Battery.step(1.0) |> Map.put(:battery, 0.1) |> Battery.step(1.0)
    assert c.battery_warned == :critical
    assert [_, <<"Battery 1 is critical ", _::binary>>] = texts(c)
  end

  test "with the failsafe on: RTL when low, LAND when critical" do
    c = in_air(ready(%{battery_failsafe: :rtl}), %{battery: 0.2005}) |> Battery.step(1.0)
    assert c.mode == :rtl and c.failsafe == :battery
    assert "Battery Failsafe" in texts(c)

    c = in_air(ready(%{battery_failsafe: :rtl}), %{battery: 0.1, battery_warned: :low}) |> Battery.step(1.0)
    assert c.mode == :land

    c = in_air(ready(%{battery_failsafe: :land}), %{battery: 0.2005}) |> Battery.step(1.0)
    assert c.mode == :land
  end
end
