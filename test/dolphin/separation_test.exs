defmodule Dolphin.SeparationTest do
  # The live separation monitor on views put in the table as a vehicle's
  # process puts them (one per frame that changes something), with this
  # test's processes standing in for the missions' executors; and its
  # prediction against brute-force sampling.
  use ExUnit.Case, async: true

  import Dolphin.Property

  alias Dolphin.{Geo, Separation}
  alias Dolphin.Separation.Prediction
  alias Dolphin.Vehicles.{View, Views}

  doctest Dolphin.Separation.Prediction

  @base Geo.location(40.444233, -7.375234, 820)
  @limits %{horizontal: 20.0, vertical: 10.0}
  # Each test's three vehicles have ids of their own: what the monitor still
  # does about another test's vehicles is no concern of this one's.
  setup do
    Dolphin.Test.Instance.start!()
    base = 10_000 + 10 * System.unique_integer([:positive, :monotonic])
    ids = {base + 1, base + 2, base + 3}
    Dolphin.Events.subscribe()
    %{ids: ids}
  end

  # A copter `north`, `east` metres from the base, 30 m up, flying at `velocity` {n, e, up} m/s
  # (`boot_ms:` the autopilot's clock when it reported so; none by default).
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
      position: Geo.offset(Keyword.get(opts, :base, @base), north, east, up),
      relative_altitude: up * 1.0,
      velocity: velocity,
      boot_ms: Keyword.get(opts, :boot_ms)
    })
  end

  # A stand-in for the process flying vehicle `id`'s mission: it registers
  # and passes on what the monitor sends it.
  # `rank`: the engine's {run, task id}, which orders tasks started together.
  defp executor(id, started_at, rank \\ nil) do
    test = self()
    instance = Dolphin.Instance.current()

    pid =
      spawn_link(fn ->
        Dolphin.Instance.put(instance)
        :ok = Separation.flying(id, started_at: started_at, rank: rank, limits: @limits)
        send(test, {:registered, id})
        forward(test)
      end)

    assert_receive {:registered, ^id}, 5_000
    pid
  end

  defp forward(test) do
    receive do
      message -> send(test, message)
    end

    forward(test)
  end

  defp no_event(name, ids) do
    receive do
      {:dolphin, :events, %{event: ^name, vehicle: v} = e} -> if v in Tuple.to_list(ids), do: flunk("unexpected #{inspect(e)}"), else: no_event(name, ids)
    after
      300 -> :ok
    end
  end

  test "of two vehicles about to cross, the one whose task started later holds, and goes on once the other has passed", %{ids: {a, b, c} = ids} do
    # a flies east along the base's parallel, b north along its meridian: they meet over the base.
    flying(a, 0, -150, {0.0, 10.0, 0.0})
    flying(b, -150, 0, {10.0, 0.0, 0.0})
    executor(a, 1_000)
    executor(b, 2_000)

    # 15 s from the crossing: beyond the horizon, nothing.
    flying(a, 0, -150, {0.0, 10.0, 0.0})
    flying(b, -150, 0, {10.0, 0.0, 0.0})
    no_event(:separation_hold, ids)

    # 6 s from it: the later one holds.
    flying(a, 0, -60, {0.0, 10.0, 0.0})
    flying(b, -60, 0, {10.0, 0.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^b, other: ^a, in_s: in_s, closest: closest}}
    assert in_s > 3 and in_s < 6 and closest < 20
    assert_receive {:dolphin, :events, %{event: :separation_hold, vehicle: ^b, other: ^a, distance: distance}}
    assert_in_delta distance, 84.9, 0.5
    refute_receive {:separation, :hold, %{vehicle: ^a}}, 200
    assert Map.take(Separation.held(), [a, b, c]) == %{b => a}

    # Stopped 55 m short of the crossing while the other crosses: held still, then clear once it is past.
    flying(b, -55, 0, {0.0, 0.0, 0.0})
    flying(a, 0, -30, {0.0, 10.0, 0.0})
    refute_receive {:separation, :clear, _}, 300
    flying(a, 0, 50, {0.0, 10.0, 0.0})
    assert_receive {:separation, :clear, %{vehicle: ^b}}, 5_000
    assert_receive {:dolphin, :events, %{event: :separation_clear, vehicle: ^b, other: ^a, held_ms: held_ms}}
    assert held_ms >= 1_000
    refute Map.has_key?(Separation.held(), b)
  end

  test "a vehicle the ground station hears but flies no mission of ours is kept clear of: the one flying ours holds", %{ids: {a, _b, c}} do
    flying(c, 0, 0, {0.0, 0.0, 0.0})
    executor(a, 1_000)
    flying(a, 0, -50, {0.0, 10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^a, other: ^c}}
  end

  test "vehicles on the ground, and a submarine beside a copter, are not kept apart", %{ids: {a, b, _c} = ids} do
    executor(a, 1_000)
    executor(b, 2_000)
    flying(a, 0, 0, {0.0, 0.0, 0.0}, landed: :on_ground, up: 0)
    flying(b, 0, 5, {0.0, 0.0, 0.0}, landed: :on_ground, up: 0)
    flying(b, 0, 5, {0.0, 0.0, 1.0}, landed: :on_ground, armed?: false, up: 0)
    no_event(:separation_hold, ids)

    flying(a, 0, 0, {0.0, 0.0, 0.0}, up: -5, airframe: :sub, landed: nil)
    flying(b, 0, 5, {0.0, 0.0, 0.0}, up: -5)
    no_event(:separation_hold, ids)
  end

  test "head-on on one line: the later one holds and, the other still coming at it once it has stopped, moves out of its way; the other never holds", %{ids: {a, b, c}} do
    executor(a, 1_000)
    executor(b, 2_000)
    flying(a, 0, -60, {0.0, 10.0, 0.0})
    flying(b, 0, 60, {0.0, -10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^b, other: ^a}}
    assert_receive {:dolphin, :events, %{event: :separation_hold, vehicle: ^b, action: :hold}}
    flying(b, 0, 55, {0.0, 0.0, 0.0})
    flying(a, 0, -20, {0.0, 10.0, 0.0})
    assert_receive {:separation, :aside, %{vehicle: ^b, other: ^a, metres: 20.0}}
    assert_receive {:dolphin, :events, %{event: :separation_hold, vehicle: ^b, action: :aside}}
    refute_receive {:separation, _, %{vehicle: ^a}}, 300
    assert Map.take(Separation.held(), [a, b, c]) == %{b => a}

    # Only once a hold.
    flying(a, 0, -10, {0.0, 10.0, 0.0})
    refute_receive {:separation, :aside, _}, 300
  end

  test "a vehicle forgotten is no longer kept clear of, even while its mission's process lives on", %{ids: {a, b, _c}} do
    executor(a, 1_000)
    flying(a, 0, 5, {0.0, 0.0, 0.0})
    Views.delete(a)
    executor(b, 2_000)
    flying(b, 0, 0, {0.0, 0.0, 0.0})
    refute_receive {:separation, :hold, %{vehicle: ^b}}, 300
  end

  test "a held vehicle forgotten is let go, and the monitor goes on judging the others", %{ids: {a, b, c}} do
    flying(b, 0, 0, {0.0, 0.0, 0.0})
    executor(b, 1_000)
    executor(a, 2_000)
    flying(a, 0, -50, {0.0, 10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^a, other: ^b}}

    Views.delete(a)
    flying(b, 0, 1, {0.0, 0.0, 0.0})
    assert_receive {:separation, :clear, %{vehicle: ^a}}, 5_000

    executor(c, 3_000)
    flying(c, 0, -50, {0.0, 10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^c, other: ^b}}
  end

  test "a vehicle far off coming fast is judged against, wherever on the map", %{ids: {a, b, c}} do
    for {base, heading} <- [{Geo.location(69.9, 25.1, 100), :east}, {Geo.location(-0.3, 178.9, 10), :north}, {@base, :east}] do
      opts = [base: base]
      # (c hovers a kilometre away, in the cells too.)
      flying(c, 0, 1_000, {0.0, 0.0, 0.0}, opts)
      # b, not ours, is 190 m off and comes at a at 22 m/s: within 20 m in 8 s.
      if heading == :east, do: flying(b, 0, 190, {0.0, -22.0, 0.0}, opts), else: flying(b, 190, 0, {-22.0, 0.0, 0.0}, opts)
      executor(a, 1_000)
      flying(a, 0, 0, {0.0, 0.0, 0.0}, opts)
      assert_receive {:separation, :hold, %{vehicle: ^a, other: ^b}}, 2_000
      for id <- [a, b, c], do: Views.delete(id)
      assert_receive {:separation, :clear, %{vehicle: ^a}}, 5_000
    end
  end

  test "a vehicle whose last view is old is judged where it has flown since, not where that view put it", %{ids: {a, b, _c}} do
    # At 10x: from a's start the two are 8 s of clock (0.8 s of real time)
    # from their closest; at 100x a loaded host's monitor judged a only once
    # they had passed each other.
    Dolphin.Clock.set_speedup(10)
    # b, ours, 700 m east flying west at 15 m/s; then nothing new from it for 30 s of clock time.
    executor(b, 1_000)
    flying(b, 0, 700, {0.0, -15.0, 0.0})
    Process.sleep(3_000)
    # a, started later, flies east at 15 m/s: b is 250 m off by now, closing at 30 m/s.
    executor(a, 2_000)
    flying(a, 0, 0, {0.0, 15.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^a, other: ^b}}, 2_000
  end

  test "a report that reaches the monitor late is judged by the autopilot's clock: where the vehicle is by now, not where the report put it", %{ids: {a, b, _c} = ids} do
    # a, started later, hovers at the base; the autopilots' clocks are ours.
    # (b, coming at it, holds: stopped, b stays clear of a, where a, held,
    # could only climb aside.)
    executor(b, 1_000)
    executor(a, 2_000)
    flying(a, 0, 0, {0.0, 0.0, 0.0})
    # b comes west at 15 m/s, 400 m off, its report on time: 280 m off in 8 s.
    flying(b, 0, 400, {0.0, -15.0, 0.0}, boot_ms: Dolphin.Clock.now_ms())
    no_event(:separation_hold, ids)
    # A report made 5 s before it came puts b 180 m off: 60 m off in 8 s, clear.
    # b has flown 75 m since: 105 m off, past a within 8 s. (Taken as made
    # when it came, this report held nothing.)
    flying(b, 0, 180, {0.0, -15.0, 0.0}, boot_ms: Dolphin.Clock.now_ms() - 5_000)
    assert_receive {:separation, :hold, %{vehicle: ^b, other: ^a, distance: distance}}, 2_000
    assert distance < 140, "b judged #{distance} m off"
  end

  test "catching up, a plane behind is not held instead: held, it would circle, not stop; the later one ahead holds as before", %{ids: {a, b, _c}} do
    executor(a, 1_000)
    executor(b, 2_000)
    flying(b, 0, 30, {0.0, 4.0, 0.0})
    flying(a, 0, 0, {0.0, 10.0, 0.0}, airframe: :plane)
    assert_receive {:separation, :hold, %{vehicle: ^b, other: ^a}}
    refute_receive {:separation, :hold, %{vehicle: ^a}}, 300
  end

  test "one line, the later one ahead and the earlier catching up with it: the one behind holds, not the one it would run into", %{ids: {a, b, c} = ids} do
    # Both east along the base's parallel at one height: b, whose task
    # started later, 30 m ahead at 4 m/s (slowing for its turn), a behind at
    # 10 m/s. Held, b would stop in a's way; a stopped stays behind b.
    executor(a, 1_000)
    executor(b, 2_000)
    flying(b, 0, 30, {0.0, 4.0, 0.0})
    flying(a, 0, 0, {0.0, 10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^a, other: ^b}}
    assert_receive {:dolphin, :events, %{event: :separation_hold, vehicle: ^a, other: ^b, action: :hold}}
    refute_receive {:separation, _, %{vehicle: ^b}}, 300
    assert Map.take(Separation.held(), [a, b, c]) == %{a => b}

    # The choice stays while a is held: b's views do not turn it round.
    flying(a, 0, 12, {0.0, 0.0, 0.0})
    flying(b, 0, 34, {0.0, 1.0, 0.0})
    refute_receive {:separation, :hold, %{vehicle: ^b}}, 300
    assert Map.take(Separation.held(), [a, b, c]) == %{a => b}

    # b turns north and goes: a goes on once clear of it.
    flying(b, 0, 40, {10.0, 0.0, 0.0})
    flying(b, 60, 40, {10.0, 0.0, 0.0})
    flying(b, 200, 40, {10.0, 0.0, 0.0})
    assert_receive {:separation, :clear, %{vehicle: ^a}}, 5_000
    no_event(:separation_hold, ids)
  end

  test "two tasks started together: the one the engine made later holds, whichever registered first", %{ids: {a, b, _c}} do
    flying(a, 0, -60, {0.0, 10.0, 0.0})
    flying(b, -60, 0, {10.0, 0.0, 0.0})
    executor(b, 1_000, {1, 3})
    executor(a, 1_200, {1, 5})
    flying(a, 0, -60, {0.0, 10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^a, other: ^b}}
  end

  test "held for a vehicle flying none of our missions, a vehicle goes on once that one starts a later mission of ours, which holds instead", %{ids: {a, b, _c}} do
    # b hovers over the base, heard but not ours; a comes at it.
    flying(b, 0, 0, {0.0, 0.0, 0.0})
    executor(a, 1_000)
    flying(a, 0, -50, {0.0, 10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^a, other: ^b}}

    # b's mission starts after a's: b is the later one, a has the right of way.
    executor(b, 2_000)
    flying(b, 0, 0, {0.0, 0.0, 0.0})
    assert_receive {:separation, :clear, %{vehicle: ^a}}
    assert_receive {:separation, :hold, %{vehicle: ^b, other: ^a}}
    assert Map.take(Separation.held(), [a, b]) == %{b => a}
  end

  test "held for a third vehicle, a vehicle goes on once that one is gone, though one held for it stands near", %{ids: {a, b, c}} do
    # c hovers over the base, not ours; a comes at it and holds.
    flying(c, 0, 0, {0.0, 0.0, 0.0})
    executor(a, 1_000)
    flying(a, 0, -50, {0.0, 10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^a, other: ^c}}
    flying(a, 0, -45, {0.0, 0.0, 0.0})

    # b, whose mission started later, comes at a and holds 10 m from it.
    executor(b, 2_000)
    flying(b, 0, -80, {0.0, 10.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^b, other: ^a}}
    flying(b, 0, -55, {0.0, 0.0, 0.0})

    # c leaves: a goes on (b, which waits for a, does not keep it), then b.
    flying(c, 500, 500, {0.0, 0.0, 0.0})
    assert_receive {:separation, :clear, %{vehicle: ^a}}, 5_000
    refute Map.has_key?(Separation.held(), a)
  end

  test "two held for a third at one place: once it is gone, the one whose task started first goes on, then the other once that one has climbed away", %{ids: {a, b, c}} do
    # c, flying none of our missions, comes down 9 m over the pad that a and
    # b, on the ground side by side and armed, are taking off from: both hold for it.
    flying(c, 0, 0, {0.0, 0.0, -1.0}, up: 9, landed: :landing)
    executor(a, 1_000)
    executor(b, 2_000)
    flying(b, 0, 1, {0.0, 0.0, 0.0}, up: 0, landed: :takeoff)
    assert_receive {:separation, :hold, %{vehicle: ^b, other: ^c}}
    flying(a, 0, 0, {0.0, 0.0, 0.0}, up: 0, landed: :takeoff)
    assert_receive {:separation, :hold, %{vehicle: ^a, other: ^c}}

    # c lands and disarms: a goes on (b, whose task started later, waits for it), b does not yet.
    flying(c, 0, 0, {0.0, 0.0, 0.0}, up: 0, landed: :on_ground, armed?: false)
    assert_receive {:separation, :clear, %{vehicle: ^a}}, 5_000
    refute_received {:separation, :clear, %{vehicle: ^b}}
    assert Map.has_key?(Separation.held(), b)

    # a climbs away: b goes on.
    flying(a, 0, 0, {0.0, 0.0, 2.5}, up: 30)
    assert_receive {:separation, :clear, %{vehicle: ^b}}, 5_000
  end

  test "two already too close but moving apart are left to part", %{ids: {a, b, _c} = ids} do
    executor(a, 1_000)
    executor(b, 2_000)
    flying(a, 0, 0, {0.0, -5.0, 0.0})
    flying(b, 0, 12, {0.0, 5.0, 0.0})
    no_event(:separation_hold, ids)
  end

  test "a mission that ends is forgotten: what it held for no longer holds the other", %{ids: {a, b, _c}} do
    flying(a, 0, -60, {0.0, 10.0, 0.0})
    flying(b, -60, 0, {10.0, 0.0, 0.0})
    first = executor(a, 1_000)
    executor(b, 2_000)
    flying(b, -60, 0, {10.0, 0.0, 0.0})
    assert_receive {:separation, :hold, %{vehicle: ^b}}

    # The first lands where it is and its mission ends.
    flying(b, -55, 0, {0.0, 0.0, 0.0})
    flying(a, 0, -30, {0.0, 0.0, 0.0}, landed: :on_ground, armed?: false, up: 0)
    Process.unlink(first)
    Process.exit(first, :kill)
    assert_receive {:separation, :clear, %{vehicle: ^b}}, 5_000
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
        # Sampled by a micrometre within the limits: two vehicles kept exactly
        # at the limit (10 m apart, climbing alike) are not lost to a sample's
        # rounding (1 + 4s and 11 + 4s came out 9.999999999 m apart).
        within = %{horizontal: @limits.horizontal - 1.0e-6, vertical: @limits.vertical - 1.0e-6}
        sampled = Enum.find(0..4_000, fn i -> not Prediction.apart?({at.(p0, v0, i * step), v0}, {at.(q0, w0, i * step), w0}, within) end)

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
