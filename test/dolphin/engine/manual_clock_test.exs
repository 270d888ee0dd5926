defmodule Dolphin.Test.ManualClockTest do
  # The manual clock (test/support/manual_clock.ex) fires a timer only once the
  # engine has settled; what counts as the engine decides whether the property
  # tests are reproducible. A named clock: not async.
  use ExUnit.Case, async: false

  alias Dolphin.Test.ManualClock

  test "a process an engine process spawned, not run yet, keeps the engine from settling" do
    start_supervised!(ManualClock)
    test = self()

    engine =
      spawn(fn ->
        Process.put(:"$dolphin_context", %{clock: ManualClock})
        child = spawn(fn -> receive do: (:go -> :ok) end)
        # What a loaded machine does to a process just spawned: it has not run
        # yet (and its dictionary is still empty).
        :erlang.suspend_process(child)
        send(test, {:child, child})
        # Only the suspender can resume it.
        receive do: (:resume -> :erlang.resume_process(child))
        receive do: (:done -> :ok)
      end)

    assert_receive {:child, child}, 30_000
    assert_raise RuntimeError, ~r/never settled: \[#{inspect(child)}\]/, fn -> ManualClock.settle(50) end

    ref = Process.monitor(child)
    send(engine, :resume)
    send(child, :go)
    assert_receive {:DOWN, ^ref, :process, ^child, :normal}, 30_000
    assert ManualClock.settle() == :ok
    send(engine, :done)
  end
end
