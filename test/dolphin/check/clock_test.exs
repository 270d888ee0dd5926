defmodule Dolphin.Check.ClockTest do
  # Busy loops of its own: not beside other tests' timing.
  use ExUnit.Case, async: false

  alias Dolphin.Check.Clock

  # Reads the dry run's time as it starts, as Dolphin.Check.Flight does.
  defmodule Starter do
    @moduledoc false
    use GenServer

    @impl true
    def init(_), do: {:ok, Clock.now_ms()}

    @impl true
    def handle_call(:started_ms, _from, t), do: {:reply, t, t}
  end

  @rounds 500

  # The clock asks the VM's processes one by one when the VM is busy: a
  # process of the dry run started while it asks, by one it asks later and
  # finds waiting for that start, was missed by the second round when that
  # round asked only the first round's processes again; time then moved on
  # before the new process read it (a stand-in flight's start time, in
  # check_test's dry runs side by side). The new process here is of low
  # priority, so that it waits for a core while the clock asks; many
  # processes of the dry run make the asking long. Before the second round
  # listed the VM anew: 2 of 200, 3 and 9 of 1,000 rounds read a later time.
  @tag timeout: 300_000
  test "a process started while the clock asks a busy VM is waited for: time does not move before it runs" do
    instance = Module.concat(Dolphin.Check.DryRun, "ClockTest")
    Dolphin.Instance.put(instance)
    busy = for _ <- 1..2, do: spawn(fn -> Stream.repeatedly(fn -> :erlang.phash2(make_ref()) end) |> Stream.run() end)

    try do
      {:ok, late} =
        Clock.within(instance, fn ->
          Clock.run(1_000_000_000, fn ->
            waiting = for _ <- 1..2_000, do: spawn(fn -> receive(do: (:never -> :ok)) end)
            me = self()
            spawn_link(fn -> send(me, {:late, starts(instance)}) end)
            late = receive(do: ({:late, late} -> late))
            Enum.each(waiting, &Process.exit(&1, :kill))
            late
          end)
        end)

      assert late == [], "#{length(late)} of #{@rounds} starts read a later time than the one they began at: #{inspect(Enum.take(late, 5))}"
    after
      Enum.each(busy, &Process.exit(&1, :kill))
    end
  end

  # Each round: a timer set half a second ahead, a little work (the clock
  # finds the dry run busy and asks again), then a process started, which
  # must read the time the round began at. [{round, began, read}] of those
  # that read another.
  defp starts(instance) do
    Dolphin.Instance.put(instance)

    for round <- 1..@rounds, reduce: [] do
      late ->
        began = Clock.now_ms()
        Clock.send_after(self(), {:round, round}, 500)
        work_until(System.monotonic_time(:microsecond) + :rand.uniform(3_000))
        {:ok, pid} = GenServer.start_link(Starter, nil, spawn_opt: [priority: :low])
        read = GenServer.call(pid, :started_ms)
        GenServer.stop(pid)
        receive(do: ({:round, ^round} -> :ok))
        if read == began, do: late, else: [{round, began, read} | late]
    end
  end

  defp work_until(t), do: if(System.monotonic_time(:microsecond) < t, do: work_until(t), else: :ok)
end
