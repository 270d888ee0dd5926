defmodule Dolphin.Test.SeparationHold do
  @moduledoc """
  The separation monitor's hold played to one mission's process
  (`Dolphin.Mission.Executor`) at a known moment: the instant the mission
  first flies, while a copter's motors still spool up on the ground.
  """

  @doc """
  The executor's start option (`Dolphin.Mission.Executor.start_link/3`)
  that sends it the monitor's hold, from within it, as it first enters
  `:flying` (once). Given at its start: installed after it, it may come
  too late (a test process descheduled while the mission starts).
  """
  def at_first_flight do
    hold_once = fn
      :waiting, {:consume, _, from, :flying}, _ when from != :flying -> send(self(), {:separation, :hold, %{}}) && :sent
      acc, _event, _state -> acc
    end

    [debug: [{:install, {hold_once, :waiting}}]]
  end

  @doc "The monitor lets `executor`'s vehicle go."
  def let_go(executor), do: send(executor, {:separation, :clear, %{}})
end
