defmodule Dolphin.SeparationTest do
  # The live separation monitor on views put in the table as a vehicle's
  # process puts them (one per frame that changes something), with this
  # test's processes standing in for the missions' executors; and its
  # prediction against brute-force sampling.
  use ExUnit.Case, async: false

  import Dolphin.Property

  alias Dolphin.{Geo, Separation}
  alias Dolphin.Separation.Prediction
  alias Dolphin.Vehicles.{View, Views}

  doctest Dolphin.Separation.Prediction

  @base Geo.location(40.444233, -7.375234, 820)
  @limits %{horizontal: 20.0, vertical: 10.0}
  @ids [201, 202, 203]

  setup do
    Dolphin.Events.subscribe()
    on_exit(fn -> Enum.each(@ids, &Views.delete/1) end)
  end

  # A copter `north`, `east` metres from the base, 30 m up, flying at `velocity` {n, e, up} m/s.
  defp flying(id, north, east, velocity, opts \\ []) do
    up = Keyword.get(opts, :up, 30)

    Views.put(%View{
      id: id,
      type: :uav,
      airframe: Keyword.get(opts, :airframe, :copter),
      mav_type: 2,
      armed?: Keyword.get(opts, :armed?, true),
      landed: Keyword.get(opts, :landed, :in_air),
      mode: :auto,
      position: Geo.offset(@base, north, east, up),
      relative_altitude: up * 1.0,
      velocity: velocity
    })
  end

  # A stand-in for the process flying vehicle `id`'s mission: it registers
  # and passes on what the monitor sends it.
  # `rank`: the engine's {run, task id}, which orders tasks started together.
  defp executor(id, started_at, rank \\ nil) do
    test = self()

    pid =
      spawn_link(fn ->
        :ok = Separation.flying(id, started_at: started_at, rank: rank, limits: @limits)
        send(test, {:registered, id})
        forward(test)
      end)

    assert_receive {:registered, ^id}
    pid
  end

  defp forward(test) do
    receive do
      message -> send(test, message)
    end

    forward(test)
  end

  defp no_event(name) do
    refute_receive {:dolphin, :events, %{event: ^name}}, 300
  end

  test "of two vehicles about to cross, the one whose task started later holds, and goes on once the other has passed" do
    # 201 flies east along the base's parallel, 202 north along its meridian: they meet over the base.
    flying(201, 0, -150, {0.0, 10.0, 0.0})
    flying(202, -150, 0, {10.0, 0.0, 0.0})
    executor(201, 1_000)
    executor(202, 2_000)

    # 15 s from the crossing: beyond the horizon, nothing.
    flying(201, 0, -150, {0.0, 10.0, 0.0})
    flying(202, -150, 0, {10.0, 0.0, 0.0})
    no_event(:separation_hold)

    # 6 s from it: the later one holds.
    flying(201, 0, -60, {0.0, 10.0, 0.0})
    flying(202, -60, 0, {10.0, 0.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: 202, other: 201, in_s: in_s, closest: closest}}
    assert in_s > 3 and in_s < 6 and closest < 20
    assert_receive {:dolphin, :events, %{event: :separation_hold, vehicle: 202, other: 201, distance: distance}}
    assert_in_delta distance, 84.9, 0.5
    refute_receive {:separation, :hold, %{vehicle: 201}}, 200
    assert Separation.held() == %{202 => 201}

    # Stopped 55 m short of the crossing while the other crosses: held still, then clear once it is past.
    flying(202, -55, 0, {0.0, 0.0, 0.0})
    flying(201, 0, -30, {0.0, 10.0, 0.0})
    refute_receive {:separation, :clear, _}, 300
    flying(201, 0, 50, {0.0, 10.0, 0.0})
    assert_receive {:separation, :clear, %{vehicle: 202}}, 5_000
    assert_receive {:dolphin, :events, %{event: :separation_clear, vehicle: 202, other: 201, held_ms: held_ms}}
    assert held_ms >= 1_000
    assert Separation.held() == %{}
  end

  test "a vehicle the ground station hears but flies no mission of ours is kept clear of: the one flying ours holds" do
    flying(203, 0, 0, {0.0, 0.0, 0.0})
    executor(201, 1_000)
    flying(201, 0, -50, {0.0, 10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: 201, other: 203}}
  end

  test "vehicles on the ground, and a submarine beside a copter, are not kept apart" do
    executor(201, 1_000)
    executor(202, 2_000)
    flying(201, 0, 0, {0.0, 0.0, 0.0}, landed: :on_ground, up: 0)
    flying(202, 0, 5, {0.0, 0.0, 0.0}, landed: :on_ground, up: 0)
    flying(202, 0, 5, {0.0, 0.0, 1.0}, landed: :on_ground, armed?: false, up: 0)
    no_event(:separation_hold)

    flying(201, 0, 0, {0.0, 0.0, 0.0}, up: -5, airframe: :sub, landed: nil)
    flying(202, 0, 5, {0.0, 0.0, 0.0}, up: -5)
    no_event(:separation_hold)
  end

  test "head-on on one line: the later one holds and, the other still coming at it once it has stopped, moves out of its way; the other never holds" do
    executor(201, 1_000)
    executor(202, 2_000)
    flying(201, 0, -60, {0.0, 10.0, 0.0})
    flying(202, 0, 60, {0.0, -10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: 202, other: 201}}
    assert_receive {:dolphin, :events, %{event: :separation_hold, vehicle: 202, action: :hold}}
    flying(202, 0, 55, {0.0, 0.0, 0.0})
    flying(201, 0, -20, {0.0, 10.0, 0.0})
    assert_receive {:separation, :aside, %{vehicle: 202, other: 201, metres: 20.0}}
    assert_receive {:dolphin, :events, %{event: :separation_hold, vehicle: 202, action: :aside}}
    refute_receive {:separation, _, %{vehicle: 201}}, 300
    assert Separation.held() == %{202 => 201}

    # Only once a hold.
    flying(201, 0, -10, {0.0, 10.0, 0.0})
    refute_receive {:separation, :aside, _}, 300
  end

  test "two tasks started together: the one the engine made later holds, whichever registered first" do
    flying(201, 0, -60, {0.0, 10.0, 0.0})
    flying(202, -60, 0, {10.0, 0.0, 0.0})
    executor(202, 1_000, {1, 3})
    executor(201, 1_200, {1, 5})
    flying(201, 0, -60, {0.0, 10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: 201, other: 202}}
  end

  test "two already too close but moving apart are left to part" do
    executor(201, 1_000)
    executor(202, 2_000)
    flying(201, 0, 0, {0.0, -5.0, 0.0})
    flying(202, 0, 12, {0.0, 5.0, 0.0})
    no_event(:separation_hold)
  end

  test "a mission that ends is forgotten: what it held for no longer holds the other" do
    flying(201, 0, -60, {0.0, 10.0, 0.0})
    flying(202, -60, 0, {10.0, 0.0, 0.0})
    first = executor(201, 1_000)
    executor(202, 2_000)
    flying(202, -60, 0, {10.0, 0.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: 202}}

    # The first lands where it is and its mission ends.
    flying(202, -55, 0, {0.0, 0.0, 0.0})
    flying(201, 0, -30, {0.0, 0.0, 0.0}, landed: :on_ground, armed?: false, up: 0)
    Process.unlink(first)
    Process.exit(first, :kill)
    assert_receive {:separation, :clear, %{vehicle: 202}}, 5_000
  end

  test "the prediction finds a loss of separation exactly when sampling the two straight paths finds one" do
    v = :proper_types.integer(-25, 25)
    p = :proper_types.integer(-300, 300)
    h = :proper_types.integer(-40, 40)

    check(
      forall({{p, p, h}, {v, v, :proper_types.integer(-5, 5)}, {p, p, h}, {v, v, :proper_types.integer(-5, 5)}, :proper_types.integer(1, 20)}, fn {p0, v0, q0, w0, horizon} ->
        at = fn {x, y, z}, {vx, vy, vz}, s -> {x + vx * s, y + vy * s, z + vz * s} end
        lost? = fn s -> not Prediction.apart?({at.(p0, v0, s), v0}, {at.(q0, w0, s), w0}, @limits) end
        step = horizon / 4_000
        sampled = Enum.find(0..4_000, &lost?.(&1 * step))

        case Prediction.conflict({p0, v0}, {q0, w0}, @limits, horizon) do
          :clear ->
            # Sampling may only miss what a grazing pass leaves between samples; what it finds
            # is a loss already there at the start, with the two moving apart.
            assert sampled == nil or (sampled == 0 and Prediction.parting?({p0, v0}, {q0, w0}, @limits))

          {:conflict, in_s, closest} ->
            assert in_s >= 0 and in_s <= horizon
            # Lost just after in_s (an open interval: at in_s it is the limit itself)...
            assert lost?.(min(in_s + 1.0e-6, horizon)) or in_s == horizon
            # ...and never before, by more than a sample.
            assert sampled == nil or sampled * step >= in_s - step
            assert closest < @limits.horizontal + 1.0e-6
        end

        true
      end),
      numtests: 300
    )
  end
end
