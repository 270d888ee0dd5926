defmodule Dolphin.Sim.Copter.Battery do
  @moduledoc false
  # The simulated copter's battery: drained while armed in proportion to
  # effort, charged while disarmed on the ground at home or at the fleet's
  # charger, its low and critical warnings, and the battery failsafe
  # (BATT_FS_LOW_ACT / BATT_FS_CRT_ACT) when enabled.

  import Dolphin.Sim.Copter, only: [text: 3, in_air?: 1, home_ne: 1, ne: 3, distance_to: 3]

  alias Dolphin.Sim.{Copter, Streams}
  alias Dolphin.Sim.Copter.Modes

  # Drain while armed, in proportion to effort; charge while disarmed on the
  # ground at home.
  @spec step(Copter.t(), float()) :: Copter.t()
  def step(c, dt) do
    if c.armed do
      speed = :math.sqrt(c.vn * c.vn + c.ve * c.ve)
      # Its airframe's energy model (the pre-flight check's), at this vehicle's settings.
      airframe = Dolphin.Airframe.of(c.config.airframe)
      amps = airframe.current(c.config, speed, c.vz, in_air?(c))
      used = amps * dt / 3.6
      remaining = max(c.battery - used / c.config.capacity_mah, 0.0)
      levels(%{c | battery: remaining, consumed_mah: c.consumed_mah + used, current_a: amps})
    else
      c = %{c | current_a: 0.0}

      if at_home?(c) and c.config.charge_rate > 0 and c.battery < 1.0 do
        battery = min(c.battery + c.config.charge_rate * dt, 1.0)
        blocked = c.arm_blocked and battery < c.config.battery_low

        %{
          c
          | battery: battery,
            consumed_mah: max(c.consumed_mah - c.config.charge_rate * dt * c.config.capacity_mah, 0.0),
            arm_blocked: blocked,
            battery_warned: if(battery >= c.config.battery_low, do: nil, else: c.battery_warned)
        }
      else
        c
      end
    end
  end

  # On the ground at its home, or at the fleet's charging station (where
  # missions written for the whole fleet bring every vehicle back).
  @spec at_home?(Copter.t()) :: boolean()
  def at_home?(%{home: nil}), do: false

  def at_home?(c) do
    {hn, he} = home_ne(c)
    near? = fn {n, e}, r -> distance_to(c, n, e) <= r end
    charger = c.config.charger
    c.landed == :on_ground and (near?.({hn, he}, 10) or (charger != nil and near?.(ne(c, charger.lat, charger.lon), 15)))
  end

  defp levels(c) do
    # An empty pack does not stop the simulated motors (as in SITL with the
    # failsafes off): only the failsafe, when enabled, acts.
    cond do
      c.battery <= c.config.battery_critical and c.battery_warned != :critical ->
        c = %{text(c, 2, "Battery 1 is critical #{volts(c)}V used #{round(c.consumed_mah)} mAh") | battery_warned: :critical, arm_blocked: true}
        failsafe(c, :land)

      c.battery <= c.config.battery_low and c.battery_warned == nil ->
        c = %{text(c, 2, "Battery 1 is low #{volts(c)}V used #{round(c.consumed_mah)} mAh") | battery_warned: :low, arm_blocked: true}
        failsafe(c, :rtl)

      true ->
        c
    end
  end

  defp volts(c), do: :erlang.float_to_binary(Streams.voltage(c) / 1000, decimals: 2)

  # BATT_FS_LOW_ACT / BATT_FS_CRT_ACT: off by default, as in ArduPilot.
  defp failsafe(%{config: %{battery_failsafe: :none}} = c, _action), do: c

  defp failsafe(c, action) do
    if in_air?(c) do
      c = %{text(c, 2, "Battery Failsafe") | failsafe: :battery}
      action = if c.config.battery_failsafe == :land, do: :land, else: action
      {_, c} = Modes.set_mode_named(c, action)
      c
    else
      c
    end
  end
end
