defmodule Dolphin.ClockTest do
  # Changes the global speed-up: not async.
  use ExUnit.Case, async: false

  alias Dolphin.Clock

  doctest Clock

  setup do
    on_exit(fn -> Clock.set_speedup(1) end)
  end

  test "clock time runs K times faster and stays continuous across a change" do
    Clock.set_speedup(50)
    t0 = Clock.now_ms()
    Process.sleep(20)
    elapsed = Clock.now_ms() - t0
    # At least 20 ms of real time passed: at least 1,000 ms of clock time.
    assert elapsed >= 1_000

    before = Clock.now_ms()
    Clock.set_speedup(1)
    assert Clock.now_ms() >= before
    assert Clock.speedup() == 1
  end

  test "timers take clock durations" do
    Clock.set_speedup(100)
    ref = Clock.send_after(self(), :ding, 5_000)
    # 5 s of clock time are 50 ms of real time: the timer's own remaining time
    # says so, however late a loaded machine delivers it.
    remaining = Process.read_timer(ref)
    assert remaining == false or remaining <= 50
    assert_receive :ding, 30_000
    assert Clock.to_real_ms(0) == 0
    assert_raise ArgumentError, ~r/a number from 0.01 to 1000/, fn -> Clock.set_speedup(0) end
  end

  test "an engine timer keeps its clock-time deadline when the clock slows down after it was set" do
    # idle 10 s of clock time: 0.5 s of real time at 20x, set when the run starts.
    Clock.set_speedup(20)
    t0 = Clock.now_ms()
    {:ok, run} = Dolphin.Engine.start(Dolphin.Engine.idle(10_000))
    Process.sleep(100)
    # Halved (the clock follows SITL vehicles that fell behind): the timer, due
    # after 0.5 s of real time, fires early and is set again for what is left.
    Clock.set_speedup(10)
    assert {:ok, :done} = Dolphin.Engine.await(run, 30_000)
    assert Clock.now_ms() - t0 >= 10_000
  end

  test "the speed-up stays within what the clock and the simulator hold" do
    for k <- [0, -1, 0.001, 1000.5, 1.0e9, :fast, "10"] do
      refute Clock.speedup?(k)
      assert_raise ArgumentError, ~r/a speed-up is a number from 0.01 to 1000 \(beyond 1000 the simulated vehicles cannot keep up/, fn -> Clock.set_speedup(k) end
    end

    Clock.set_speedup(1000)
    assert Clock.speedup() == 1000
    Clock.set_speedup(0.01)
    assert Clock.speedup() == 0.01
    # A timer holds 2^32 - 1 ms of real time: that much clock time times the speed-up.
    assert Clock.max_wait_ms(0.01) == 42_949_672
  end
end
