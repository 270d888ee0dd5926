defmodule Dolphin.CLI.SignalsTest do
  # Signals this test VM itself: nothing else may catch them meanwhile. Each
  # catcher is sent one signal only: a second, later one would end this VM
  # (the tasks' "again: exiting at once"; it and the repeats are tested on
  # the tasks as OS processes, test/mix/tasks/*signals_test.exs). A test
  # process that ends releases what it caught.
  use ExUnit.Case, async: false

  alias Dolphin.CLI.Signals

  doctest Signals

  defp kill_self(signal), do: {_, 0} = System.cmd("kill", ["-#{signal}", System.pid()])

  defp handlers, do: Enum.sort(:gen_event.which_handlers(:erl_signal_server))

  # The handler there before anything was caught: OTP's, or under `mix test`
  # the one of mix.exs that makes a killed suite exit 143.
  setup do
    %{before: handlers()}
  end

  test "while caught, SIGTERM (and SIGINT, with the C library) come as messages; released, the handler before is back", %{before: before} do
    caught = Signals.catch_signals(self())
    assert :sigterm in caught
    assert Signals in handlers()

    kill_self("TERM")
    assert_receive {:dolphin_signal, :sigterm}, 10_000
    assert :ok = Signals.release_signals()

    # Without the library SIGINT would open the BREAK menu of this VM: only signalled when caught.
    if :sigint in Signals.catch_signals(self()) do
      kill_self("INT")
      assert_receive {:dolphin_signal, :sigint}, 10_000
    end

    assert :ok = Signals.release_signals()
    assert handlers() == before
    refute Signals in handlers()
  end

  test "a catcher caught above another gets the signals until it releases them, then the one below does", %{before: before} do
    me = self()

    above =
      spawn_link(fn ->
        receive(do: (:go -> Signals.catch_signals(self())))
        send(me, :caught)
        receive(do: ({:dolphin_signal, _} = msg -> send(me, {:above, msg})))
        receive(do: (:release -> Signals.release_signals()))
        send(me, :released)
        receive(do: (:never -> :ok))
      end)

    Signals.catch_signals(self())
    send(above, :go)
    assert_receive :caught, 5_000
    kill_self("TERM")
    assert_receive {:above, {:dolphin_signal, :sigterm}}, 10_000
    refute_received {:dolphin_signal, _}

    send(above, :release)
    assert_receive :released, 5_000
    kill_self("TERM")
    assert_receive {:dolphin_signal, :sigterm}, 10_000

    Signals.release_signals()
    assert handlers() == before
  end

  test "a catcher that ends without releasing them gives them back", %{before: before} do
    catcher = spawn(fn -> receive(do: (:never -> :ok)) end)
    Signals.catch_signals(catcher)
    assert Signals in handlers()

    ref = Process.monitor(catcher)
    Process.exit(catcher, :kill)
    assert_receive {:DOWN, ^ref, _, _, _}
    Dolphin.Test.Wait.until(fn -> handlers() == before end)
    refute Signals in handlers()
  end

  test "caught again by the same process, only the options change: one release gives the signals back", %{before: before} do
    Signals.catch_signals(self())
    Signals.catch_signals(self(), again: fn _ -> :ok end)
    kill_self("TERM")
    assert_receive {:dolphin_signal, :sigterm}, 10_000

    Signals.release_signals()
    assert handlers() == before
  end

  test "a task called from a test or from IEx leaves the signals alone", %{before: before} do
    refute Signals.command?("dolphin.run")
    refute Signals.exit_on_signal("dolphin.run", "no script was running; exiting")
    assert handlers() == before
  end

  test "the C library is built and loaded on this machine (it has a C compiler)" do
    caught = Signals.catch_signals(self())
    Signals.release_signals()
    assert caught == [:sigint, :sigterm]
  end
end
