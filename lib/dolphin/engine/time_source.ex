defmodule Dolphin.Engine.TimeSource do
  @moduledoc """
  Where the engine's timers come from. By default `Dolphin.Engine.TimeSource.Clock`,
  that is `Dolphin.Clock`, so a speed-up applies to every `idle`, `during`,
  `pause`, condition tick and stop bound. A run can be given another module
  (`Dolphin.Engine.run(task, clock: ManualClock)`): the property tests use a
  manual clock that only moves when told, so that the order of events is
  exactly reproducible.
  """

  @doc "Clock time now, in milliseconds."
  @callback now_ms() :: integer()
  @doc "Sends `msg` to `pid` after `ms` of clock time; returns a reference for `c:cancel/1`."
  @callback send_after(pid(), term(), non_neg_integer()) :: reference()
  @doc "Cancels a timer (no error if it already fired)."
  @callback cancel(reference()) :: :ok
  @doc "Sleeps the caller for `ms` of clock time."
  @callback sleep(non_neg_integer()) :: :ok
  @doc "Real milliseconds to wait in a `receive ... after` for `ms` of clock time (bounds, not timers)."
  @callback real_ms(non_neg_integer()) :: non_neg_integer()
end

defmodule Dolphin.Engine.TimeSource.Clock do
  @moduledoc "The default time source: `Dolphin.Clock`, with its speed-up."
  @behaviour Dolphin.Engine.TimeSource

  @impl true
  defdelegate now_ms(), to: Dolphin.Clock
  @impl true
  defdelegate send_after(pid, msg, ms), to: Dolphin.Clock
  @impl true
  defdelegate sleep(ms), to: Dolphin.Clock
  @impl true
  def cancel(ref) do
    Process.cancel_timer(ref, info: false)
    :ok
  end
  # Bounds never shrink below 2 s of real time: at a high speed-up, vehicles
  # still answer over a real network.
  @impl true
  def real_ms(ms), do: max(Dolphin.Clock.to_real_ms(ms), 2_000)
end
