defmodule Dolphin.Test.Wait do
  @moduledoc """
  Waiting in tests for something that happens in other processes: polls a
  function every 20 ms until it returns a truthy value (returned), and fails
  the test after `tries` polls (default 1_500, at least 30 s).

  The bound only turns a hang into a failure: what is awaited does come, but
  on a loaded machine (CI, shared hosts) it can take seconds, so the bound is
  far above what any run needs.
  """

  import ExUnit.Assertions

  @doc "Polls `fun` until it is truthy; `describe` (a function) adds context to the failure."
  def until(fun, tries \\ 1_500, describe \\ fn -> "" end) do
    case fun.() do
      result when result in [nil, false] ->
        if tries == 0, do: flunk("condition not met in time " <> describe.()), else: (Process.sleep(20); until(fun, tries - 1, describe))

      result ->
        result
    end
  end

  @doc """
  The `Dolphin.Events` events in the caller's mailbox (after
  `Dolphin.Events.subscribe/0`), oldest first, taken out of it; waits
  for none.
  """
  def received_events(acc \\ []) do
    receive do
      {:dolphin, :events, e} -> received_events([e | acc])
    after
      0 -> Enum.reverse(acc)
    end
  end
end
