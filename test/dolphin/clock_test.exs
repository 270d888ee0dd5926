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
    assert_raise ArgumentError, ~r/positive number/, fn -> Clock.set_speedup(0) end
  end
end
