defmodule Dolphin.Vehicles.ManoeuvresTest do
  # ArduCopter's manoeuvres against a simulated copter over UDP on 127.0.0.1. Its own
  # Dolphin.Instance (its vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.{CommandError, ManoeuvreError, Sim, Vehicles}
  alias Dolphin.Test.Wait
  alias Dolphin.Vehicles.Manoeuvres

  doctest Dolphin.ManoeuvreError

  @speedup 50

  describe "in_air?/1" do
    test "armed, and flying by EXTENDED_SYS_STATE or, without it, more than a metre above home" do
      view = fn fields -> struct!(Dolphin.Vehicles.View, fields) end
      assert Manoeuvres.in_air?(view.(armed?: true, landed: :in_air))
      assert Manoeuvres.in_air?(view.(armed?: true, landed: :takeoff))
      refute Manoeuvres.in_air?(view.(armed?: false, landed: :in_air))
      refute Manoeuvres.in_air?(view.(armed?: true, landed: :on_ground, relative_altitude: 30.0))
      assert Manoeuvres.in_air?(view.(armed?: true, landed: nil, relative_altitude: 1.5))
      refute Manoeuvres.in_air?(view.(armed?: true, landed: nil, relative_altitude: 0.4))
      refute Manoeuvres.in_air?(view.(armed?: true, landed: nil))
    end
  end

  describe "against a simulated copter" do
    setup ctx do
      port = Dolphin.Test.GroundStation.open()
      # Arming is refused until its position estimate is ready, that long (clock time) after boot.
      # DISARM_DELAY (10 s, 0.2 s of real time at 50x) is off where a test keeps a copter armed on the ground.
      {:ok, [1]} = Sim.start(count: 1, gcs: port, speedup: @speedup, ekf_ready_ms: Map.get(ctx, :ekf_ready_ms, 150_000), disarm_delay_ms: Map.get(ctx, :disarm_delay_ms, 10_000))
      # Without a position estimate, a copter has no home: heard and booted is enough then.
      Wait.until(fn -> if ctx[:ekf_ready_ms], do: Vehicles.ready?(1), else: match?({:ok, %{home: %{}, position: %{}}}, Vehicles.state(1)) end)
      :ok
    end

    test "take off: GUIDED, arm once the autopilot is ready, NAV_TAKEOFF; go to; hold; land" do
      me = self()
      {:ok, %{time_ms: booted_ms}} = Sim.info(1)
      assert :ok = Manoeuvres.take_off(1, 10, within: 300_000, report: &send(me, {:report, &1}))
      assert_received {:report, {:accepted, :guided}}

      # Refused while the position estimate was not ready (each new refusal reported once).
      if booted_ms < 140_000 do
        assert_received {:report, {:refused, :arm, %CommandError{}, _texts, left}} when left > 0
      end

      assert_received {:report, {:accepted, :arm}}
      assert_received {:report, {:accepted, :take_off}}

      Wait.until(fn -> match?({:ok, %{position: %{relative_alt: a}}} when a > 9.5, Vehicles.state(1)) end)
      {:ok, view} = Vehicles.view(1)
      assert Manoeuvres.in_air?(view)

      {:ok, %{home: h}} = Vehicles.state(1)
      assert :ok = Manoeuvres.go_to(1, {h.lat + 0.0002, h.lon, 15})
      Wait.until(fn -> match?({:ok, %{position: %{relative_alt: a}}} when a > 14.5, Vehicles.state(1)) end)

      # In GUIDED it holds already: nothing is sent.
      assert :ok = Manoeuvres.hold(1)
      assert {:ok, %{mode: :guided}} = Sim.info(1)
      # Told its telemetry may be stale, it is held whatever it says: BRAKE.
      assert :ok = Manoeuvres.hold(1, fresh: true)
      assert {:ok, %{mode: :brake, armed: true}} = Sim.info(1)

      assert :ok = Manoeuvres.land(1)
      Wait.until(fn -> match?({:ok, %{armed: false}}, Sim.info(1)) end)
      # A copter its autopilot lands, or one disarmed on the ground, is left alone.
      assert :ok = Manoeuvres.hold(1)
    end

    test "GUIDED is not asked for again while the view says GUIDED, unless forced (the view may lag a mode just accepted)" do
      me = self()
      report = &send(me, {:report, &1})
      Wait.until(fn -> Manoeuvres.guided(1) == :ok end)
      Wait.until(fn -> match?({:ok, %{mode: :guided}}, Vehicles.view(1)) end)
      assert :ok = Manoeuvres.guided(1, report: report)
      refute_received {:report, _}
      assert :ok = Manoeuvres.guided(1, report: report, force: true)
      assert_received {:report, {:accepted, :guided}}
    end

    @tag ekf_ready_ms: 3_600_000
    test "arming refused for longer than the bound: the error says for how long and what the autopilot said" do
      assert :ok = Manoeuvres.guided(1)
      assert {:error, %ManoeuvreError{manoeuvre: :arm, vehicle: 1, refusal: %CommandError{}, waited_ms: 2_000} = e} = Manoeuvres.arm_when_ready(1, within: 2_000)
      assert Exception.message(e) =~ ~r/^arming refused for 2 s: the autopilot says "(Pre)?Arm: .*Need Position Estimate/
      {:ok, st} = Vehicles.state(1)
      refute st.armed

      # Once only, and the take-off stops there.
      assert {:error, %ManoeuvreError{action: "arming", waited_ms: 0}} = Manoeuvres.take_off(1, 10, within: 0)

      # A command the vehicle refuses (a take-off disarmed) is an error with the refusal.
      assert {:error, %ManoeuvreError{manoeuvre: :command, action: "take-off", refusal: %CommandError{vehicle: 1}} = e} = Manoeuvres.command(1, "take-off", fn -> Vehicles.takeoff(1, 10) end)

      assert Exception.message(e) =~ ~r/^take-off refused: vehicle 1 refused MAV_CMD_NAV_TAKEOFF/
    end

    @tag disarm_delay_ms: 0
    test "a vehicle armed on the ground, in a mode that does not hold, is held by disarming it" do
      Wait.until(fn -> Manoeuvres.guided(1) == :ok end)
      assert :ok = Manoeuvres.arm_when_ready(1, within: 300_000)
      assert {:ok, :accepted} = Vehicles.set_mode(1, :loiter)
      Wait.until(fn -> match?({:ok, %{armed: true, mode: :loiter, landed: :on_ground}}, Vehicles.state(1)) end)
      assert :ok = Manoeuvres.hold(1)
      assert {:ok, %{armed: false}} = Sim.info(1)
    end
  end

  test "a vehicle the ground station does not know needs no holding" do
    assert :ok = Manoeuvres.hold(199)
  end
end
