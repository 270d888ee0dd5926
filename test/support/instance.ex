defmodule Dolphin.Test.Instance do
  @moduledoc """
  A `Dolphin.Instance` of the test's own: its vehicles, links, simulated
  vehicles, events and clock are not another test's, so the test module can
  be `async: true` even when it flies a fleet at its own speed-up. The
  instance stops when the test ends (before its `on_exit` callbacks), and
  everything in it with it.

      setup do
        Dolphin.Test.Instance.start!()
        :ok
      end

  The test process works in it (`Dolphin.Instance.put/1`); so does every
  process it starts (see `Dolphin.Instance.current/0`). An `on_exit`
  callback runs elsewhere: it calls `within/2` to work in the test's instance
  (nothing is left to clean there once the instance is gone).
  """

  import ExUnit.Callbacks, only: [start_supervised!: 1]

  @doc "Starts the test's instance and works in it; returns its name."
  def start! do
    name = :"dolphin_test_#{System.unique_integer([:positive])}"
    start_supervised!({Dolphin.Instance, name: name})
    Dolphin.Instance.put(name)
    name
  end

  @doc "`ExUnit.Callbacks.on_exit/1` for `fun`, run in the calling process's instance (`within/2`)."
  def on_exit(fun) do
    instance = Dolphin.Instance.current()
    ExUnit.Callbacks.on_exit(fn -> within(instance, fun) end)
  end

  @doc "Runs `fun` in `instance` if it is still running; nothing otherwise."
  def within(instance, fun) do
    if Dolphin.Instance.running?(instance) do
      previous = Dolphin.Instance.put(instance)

      try do
        fun.()
      after
        Dolphin.Instance.put(previous || Dolphin.Instance.default())
      end
    end

    :ok
  end
end
