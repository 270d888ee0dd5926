defmodule Dolphin.Check.ClockTest do
  # The dry run's clock moves on while one of its processes never waits only
  # when that process runs (a busy loop), not when it cannot run.
  use ExUnit.Case, async: true

  alias Dolphin.Check.Clock

  # The clock's patience with a dry run that is not idle, in real time.
  @patience_ms 2_000

  setup do
    # Something outside the dry run keeps the VM busy, as other tests and
    # dry runs do on a loaded host: the clock must ask the dry run's own
    # processes whether they wait.
    busy = spawn(fn -> spin() end)
    instance = Module.concat(__MODULE__, DryRun)
    Dolphin.Instance.put(instance)

    on_exit(fn -> Process.exit(busy, :kill) end)
    {:ok, instance: instance}
  end

  test "a dry run's process that gets no core holds the clock; a busy loop of its own holds it only for a while", ctx do
    assert {:ok, :ok} =
             Clock.within(ctx.instance, fn ->
               Clock.run(3_600_000, fn ->
                 # Ready to run but not running: as a process on a loaded host
                 # that gets no core. Time waits for it, however long.
                 starved = spawn(fn -> receive(do: (:go -> :ok)) end)
                 :erlang.suspend_process(starved)
                 Clock.send_after(self(), :tick, 1_000)
                 refute_receive :tick, @patience_ms + 1_000
                 assert Clock.now_ms() == 0
                 :erlang.resume_process(starved)
                 send(starved, :go)
                 assert_receive :tick, 30_000
                 assert Clock.now_ms() == 1_000

                 # A process of the dry run that never waits: time moves on
                 # after the patience, as it runs.
                 spinner = spawn(fn -> spin() end)
                 Clock.send_after(self(), :tock, 1_000)
                 assert_receive :tock, 30_000
                 assert Clock.now_ms() == 2_000
                 Process.exit(spinner, :kill)
                 :ok
               end)
             end)
  end

  defp spin, do: spin_on(0)
  defp spin_on(n), do: spin_on(:erlang.phash2(n + 1))
end
