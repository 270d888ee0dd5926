defmodule Dolphin.Sim.Copter.ModesTest do
  # The simulated copter's modes and arming, on the model's state directly.
  use ExUnit.Case, async: true

  alias Dolphin.Sim.Copter
  alias Dolphin.Sim.Copter.Modes

  @home %{lat: 40.444233, lon: -7.375234, alt: 820.0}

  defp boot(config \\ %{}), do: Copter.new(1, @home, Map.merge(%{ekf_ready_ms: 1_000}, config))
  defp ready(config \\ %{}), do: boot(config) |> Copter.step(1_000) |> Copter.flush() |> elem(1)
  defp in_air(c, fields \\ %{}), do: struct(c, Map.merge(%{mode: :guided, armed: true, landed: :in_air, alt: @home.alt + 20, nav: {:hold, 0.0, 0.0, @home.alt + 20}}, fields))
  defp last_text(c), do: Enum.find_value(c.out, fn {_, m} -> Map.get(m, :text) end)

  test "arming is refused, with ArduCopter's reason, until the vehicle is ready; a forced arm skips the checks" do
    {4, c} = Modes.arm(boot(), false)
    assert last_text(c) == "Arm: Need Position Estimate"
    assert {0, %{armed: true}} = Modes.arm(boot(), true)

    {4, c} = Modes.arm(%{ready() | mode: :rtl}, false)
    assert last_text(c) == "Arm: RTL mode not armable"
    {4, c} = Modes.arm(%{ready() | battery: 0.1}, false)
    assert last_text(c) == "Arm: Battery 1 below minimum arming capacity"

    {0, c} = Modes.arm(%{ready() | mode: :guided}, false)
    assert c.armed and c.ground_since == c.time_ms and last_text(c) == "Arming motors"
    assert {0, ^c} = Modes.arm(c, false)
  end

  test "disarming in the air is refused unless forced" do
    c = in_air(ready())
    {4, c} = Modes.disarm(c, false)
    assert c.armed and last_text(c) == "Disarm: vehicle is flying"
    {0, c} = Modes.disarm(c, true)
    refute c.armed
    assert c.nav == :idle and c.landed == :in_air
  end

  test "modes needing a position are refused before the estimate is ready; AUTO needs a mission" do
    {4, c} = Modes.set_mode_named(boot(), :loiter)
    assert last_text(c) == "Mode change to LOITER failed: requires position"
    assert {0, %{mode: :guided}} = Modes.set_mode_named(boot(), :guided)

    {4, c} = Modes.set_mode_named(ready(), :auto)
    assert last_text(c) == "Mode change to AUTO failed: no mission"

    # By ArduCopter number (5 LOITER); an unknown number is refused.
    assert {0, %{mode: :loiter}} = Modes.set_mode(ready(), 5)
    assert {4, %{mode: :stabilize}} = Modes.set_mode(ready(), 99)
  end

  test "what entering a mode in the air does: GUIDED and BRAKE stop, pilot modes sink, RTL climbs, LAND descends" do
    c = in_air(ready(), %{mode: :loiter})
    assert {0, %{nav: {:brake}}} = Modes.set_mode_named(c, :guided)
    assert {0, %{nav: {:brake}}} = Modes.set_mode_named(c, :brake)
    assert {0, %{nav: {:descend}}} = Modes.set_mode_named(c, :alt_hold)
    assert {0, %{nav: {:rtl, :climb}}} = Modes.set_mode_named(c, :rtl)
    assert {0, %{nav: {:land, 0.0, 0.0}, landed: :landing}} = Modes.set_mode_named(c, :land)
  end

  test "RTL or LAND armed on the ground disarms at once" do
    {0, c} = Modes.arm(%{ready() | mode: :guided}, false)
    {0, c} = Modes.set_mode_named(c, :land)
    refute c.armed
    assert last_text(c) == "Disarming motors"
  end

  test "disarms itself after DISARM_DELAY armed on the ground with nothing to do" do
    {0, c} = Modes.arm(%{ready() | mode: :guided}, false)
    assert Modes.auto_disarm(%{c | time_ms: c.time_ms + 9_999}).armed
    refute Modes.auto_disarm(%{c | time_ms: c.time_ms + 10_000}).armed
    # DISARM_DELAY 0 turns it off (ArduCopter's auto_disarm_check).
    assert Modes.auto_disarm(%{c | time_ms: c.time_ms + 3_600_000, config: %{c.config | disarm_delay_ms: 0}}).armed
  end

  # ArduCopter SITL (docs/ardupilot.md): held in BRAKE while its motors spool
  # up for a take-off, it never leaves the ground and disarms 10-12 s later.
  test "put in BRAKE while its motors spool up, it stays on the ground and disarms itself after DISARM_DELAY" do
    {0, c} = Modes.arm(%{ready() | mode: :guided}, false)
    c = Dolphin.Sim.Copter.Flight.start_takeoff(c, @home.alt + 20)
    c = Copter.step(c, 1_000)
    assert c.landed == :takeoff
    {0, c} = Modes.set_mode_named(c, :brake)
    braked = c.time_ms
    c = Enum.reduce(1..99, c, fn _, c -> Copter.step(c, 100) end)
    assert c.armed and c.landed == :on_ground and c.alt == @home.alt
    c = Enum.reduce(1..2, c, fn _, c -> Copter.step(c, 100) end)
    refute c.armed
    assert (c.time_ms - braked) in 10_000..10_200
  end

  test "the GCS failsafe returns home after 5 s without the ground station, when enabled" do
    c = in_air(ready(%{gcs_failsafe: true}), %{gcs_heard_ms: 1_000})
    assert Modes.gcs_failsafe(%{c | time_ms: 6_000}).mode == :guided
    c = Modes.gcs_failsafe(%{c | time_ms: 6_001})
    assert c.mode == :rtl and c.failsafe == :gcs

    off = in_air(ready(), %{gcs_heard_ms: 1_000, time_ms: 60_000})
    assert Modes.gcs_failsafe(off).mode == :guided
  end
end
