defmodule Dolphin.CLI.SignalsTest do
  # Signals this test VM itself: nothing else may catch them meanwhile.
  use ExUnit.Case, async: false

  alias Dolphin.CLI.Signals

  doctest Signals

  defp kill_self(signal), do: {_, 0} = System.cmd("kill", ["-#{signal}", System.pid()])

  test "while caught, SIGTERM (and SIGINT, with the C library) come as messages; released, OTP's handler is back" do
    caught = Signals.catch_signals(self())
    on_exit(&Signals.release_signals/0)
    assert :sigterm in caught
    refute :erl_signal_handler in :gen_event.which_handlers(:erl_signal_server)

    kill_self("TERM")
    assert_receive {:dolphin_signal, :sigterm}, 10_000

    # Without the library SIGINT would open the BREAK menu of this VM: only signalled when caught.
    if :sigint in caught do
      kill_self("INT")
      assert_receive {:dolphin_signal, :sigint}, 10_000
    end

    assert :ok = Signals.release_signals()
    handlers = :gen_event.which_handlers(:erl_signal_server)
    assert :erl_signal_handler in handlers
    refute Signals in handlers
  end

  test "the C library is built and loaded on this machine (it has a C compiler)" do
    caught = Signals.catch_signals(self())
    Signals.release_signals()
    assert caught == [:sigint, :sigterm]
  end
end
