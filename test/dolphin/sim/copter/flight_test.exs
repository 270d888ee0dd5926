defmodule Dolphin.Sim.Copter.FlightTest do
  # The simulated copter's kinematics, on the model's state directly.
  use ExUnit.Case, async: true

  alias Dolphin.Sim.Copter
  alias Dolphin.Sim.Copter.Flight

  @home %{lat: 40.444233, lon: -7.375234, alt: 820.0}

  # Armed and flying at `up` metres above the ground, at rest, going nowhere.
  defp flying(up, fields \\ %{}) do
    c = Copter.new(1, @home, %{ekf_ready_ms: 0}) |> Copter.step(50)
    struct(c, Map.merge(%{mode: :guided, armed: true, landed: :in_air, alt: @home.alt + up, nav: {:hold, 0.0, 0.0, @home.alt + up}}, fields))
  end

  # Steps of 50 ms, the vehicle's clock moved along (Copter.step/2 does that).
  defp fly(c, seconds, land_detector \\ false) do
    Enum.reduce(1..round(seconds * 20), c, fn _, c ->
      c = Flight.fly(%{c | time_ms: c.time_ms + 50}, 0.05)
      if land_detector, do: Flight.touchdown(c), else: c
    end)
  end
  defp ground_speed(c), do: :math.sqrt(c.vn * c.vn + c.ve * c.ve)

  test "accelerate/3 reaches the wanted velocity, or moves toward it by at most the allowed change" do
    assert Flight.accelerate({1.0, 1.0}, {1.5, 1.0}, 1.0) == {1.5, 1.0}
    {vn, ve} = Flight.accelerate({0.0, 0.0}, {3.0, 4.0}, 1.0)
    assert_in_delta vn, 0.6, 1.0e-12
    assert_in_delta ve, 0.8, 1.0e-12
  end

  test "toward/4: nothing to do at the point; at most the cruise and climb speeds far away; slower near it" do
    c = flying(20)
    assert Flight.toward(c, 0.0, 0.0, c.alt) == {0.0, 0.0, 0.0}

    {wn, we, wz} = Flight.toward(c, 3_000.0, 4_000.0, c.alt + 100)
    assert_in_delta :math.sqrt(wn * wn + we * we), c.speed, 1.0e-9
    assert_in_delta wn / we, 0.75, 1.0e-9
    assert wz == c.config.climb_speed

    {wn, _, wz} = Flight.toward(c, 2.0, 0.0, c.alt - 100)
    assert_in_delta wn, :math.sqrt(2 * c.config.accel * 2.0) * 0.8, 1.0e-9
    assert wz == -c.config.descent_speed
  end

  test "flies to a point and stops there, heading along the way" do
    c = flying(20, %{nav: {:goto, 100.0, 0.0, @home.alt + 20}}) |> fly(60)
    assert_in_delta c.n, 100.0, 0.5
    assert_in_delta c.e, 0.0, 1.0e-9
    assert ground_speed(c) < 0.2
    assert c.heading == 0.0
  end

  test "brakes harder than it accelerates, then holds where it stopped" do
    c = flying(20, %{vn: 10.0, nav: {:brake}})
    c = Flight.fly(c, 0.05)
    assert_in_delta c.vn, 10.0 - c.config.brake_accel * 0.05, 1.0e-9

    c = fly(c, 5)
    assert {:hold, n, _e, _alt} = c.nav
    assert n > 5.0
  end

  test "circles at its radius, counting the turns in radians" do
    c = flying(20, %{n: 10.0, nav: {:circle, 0.0, 0.0, @home.alt + 20, 10.0, 0.0, nil}}) |> fly(120)
    assert_in_delta :math.sqrt(c.n * c.n + c.e * c.e), 10.0, 1.0
    {:circle, _, _, _, _, turned, _} = c.nav
    # CIRCLE_RATE 20 °/s caps a 10 m circle at 3.5 m/s: about 6.7 turns in two minutes.
    assert turned > 5 * 2 * :math.pi()
  end

  test "spools up for 3 s before it climbs, and is in the air past a metre" do
    c = flying(0, %{landed: :on_ground, nav: :idle}) |> Flight.start_takeoff(@home.alt + 10)
    assert c.landed == :takeoff
    c = fly(c, 2.9)
    assert c.alt == @home.alt
    c = fly(c, 5, true)
    assert c.landed == :in_air and c.alt > @home.alt + 1
  end

  test "disarmed in the air, it falls to the ground and no further" do
    c = flying(4, %{armed: false})
    c = Flight.fly(c, 0.05)
    assert c.vz == -8.0
    c = fly(c, 2)
    assert c.alt - @home.alt < 0.05 and c.vz == 0.0
  end

  test "the land detector disarms on touchdown" do
    c = flying(0.1, %{mode: :land, landed: :landing, nav: {:land, 0.0, 0.0}})
    c = fly(c, 1, true)
    assert c.landed == :on_ground and not c.armed and c.nav == :idle
    assert {1, %{text: "Disarming motors"}} = hd(c.out)
  end

  test "a GUIDED target is taken only in GUIDED and in the air" do
    target = Copter.offset(@home, 50, 0)
    assert {:ok, %{nav: {:goto, n, _, alt}}} = Flight.guided_goto(flying(10), target.lat, target.lon, {6, 30})
    assert_in_delta n, 50.0, 1.0e-6
    assert alt == @home.alt + 30
    assert {:error, _} = Flight.guided_goto(flying(10, %{mode: :loiter}), target.lat, target.lon, 850)
    assert {:error, _} = Flight.guided_goto(flying(0, %{landed: :on_ground}), target.lat, target.lon, 850)
  end
end
