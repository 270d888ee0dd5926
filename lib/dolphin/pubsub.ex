defmodule Dolphin.PubSub do
  @moduledoc """
  Publish/subscribe on a `Registry` with duplicate keys: a subscriber registers
  itself under a topic and receives `{:dolphin, topic, event}` messages. The
  registry monitors subscribers, so one that dies is dropped without help.

  Topics: `{:vehicle, sysid}` (that vehicle's `Dolphin.Vehicles.View`,
  whole, as `{:view, view}` on each change, from its owner through
  `Dolphin.Vehicles.Views.put/1`: a vehicle's one topic), `:vehicles`
  (discoveries, losses, reconnections and forgettings of every vehicle,
  derived from the views by `Dolphin.Vehicles.Views`, and
  `{:vehicle_changed, id}` when a view changes what picks match on),
  `:events` (`Dolphin.Events`) and `{:dolphin_signals, table}` (a script's
  signals).

  Published data is a notice of a change: the data itself has one owner
  (`Dolphin.Vehicles.Views` for views, a signal table for signals), which
  anyone may read; a subscriber takes what a notice carries whole (the
  engine's condition watchers hold the latest views as their snapshot) and
  never rebuilds the owner's data from changes.

  Each `Dolphin.Instance` has its own (named `Dolphin.PubSub` in the
  default instance): a process subscribes and publishes in the instance it
  works in.
  """

  @doc false
  def child_spec(opts), do: Registry.child_spec(keys: :duplicate, name: Keyword.fetch!(opts, :name), partitions: 1)

  @doc "Subscribes the calling process to `topic`."
  @spec subscribe(term()) :: :ok
  def subscribe(topic) do
    {:ok, _} = Registry.register(registry(), topic, nil)
    :ok
  end

  @doc "Unsubscribes the calling process from `topic`."
  @spec unsubscribe(term()) :: :ok
  def unsubscribe(topic), do: Registry.unregister(registry(), topic)

  @doc "Sends `{:dolphin, topic, event}` to every subscriber of `topic`."
  @spec publish(term(), term()) :: :ok
  def publish(topic, event) do
    Registry.dispatch(registry(), topic, fn entries ->
      for {pid, _} <- entries, do: send(pid, {:dolphin, topic, event})
    end)
  end

  defp registry, do: Dolphin.Instance.names().pubsub
end
