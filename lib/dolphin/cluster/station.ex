defmodule Dolphin.Cluster.Station do
  @moduledoc """
  The station side of a cluster of ground stations: one process per node,
  member of the `:stations` group of the `Dolphin.Cluster` `:pg` scope, that
  tells subscribed controllers (`Dolphin.Cluster.Mirror` processes on other
  nodes) about the vehicles this node hears.

  It costs nothing while no controller is subscribed: only then does it
  follow the local vehicles (topic `:vehicles`, and each vehicle's
  `{:vehicle, id}`). Vehicles that this node only
  mirrors from other stations are never passed on (no loops between nodes).

  Messages to each subscriber, `{:dolphin_station, station_pid, event}`:

    * `{:hello, info}` — on subscription: `%{node, speedup, vehicles: [{id, vehicle_pid, view}]}`;
    * `{:discovered, id, vehicle_pid, view}`, `{:lost, id}`,
      `{:reconnected, id}`, `{:forgotten, id}`;
    * `{:view, id, view}` — each new view of a vehicle, whole, as soon as
      it is published here (a controller's conditions react to it: nothing
      waits to be batched);
    * `{:batch, events}` — several of the events above, in the order they
      came: those that were already waiting when this process took the
      first (at most 64), so that a busy station sends one
      message where it would send dozens, and a quiet one sends each alone;
    * `{:heard, %{id => {age_ms, link}}}` — every `:heard_every_ms` of real
      time: how long ago (clock ms) each vehicle's last frame came and its
      link figures, so that a controller tells a stale station (it stops
      hearing a vehicle) from a quiet vehicle.
  """

  use GenServer

  alias Dolphin.{Clock, PubSub, Vehicles}
  alias Dolphin.Vehicles.Views

  @heard_every_ms 250
  # At most this many events in one {:batch, events} message.
  @events_at_once 64

  @doc false
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts, name: __MODULE__)

  @doc """
  Subscribes `mirror` (a pid, usually on another node) to `station`; the
  station monitors it and answers with its `{:hello, info}` as the reply.
  """
  @spec subscribe(pid(), pid()) :: {:ok, map()} | {:error, term()}
  def subscribe(station, mirror) do
    GenServer.call(station, {:subscribe, mirror}, 10_000)
  catch
    :exit, reason -> {:error, reason}
  end

  @impl true
  def init(opts) do
    :ok = :pg.join(Dolphin.Cluster.scope(), :stations, self())
    {:ok, %{subscribers: %{}, vehicles: %{}, heard_every_ms: Keyword.get(opts, :heard_every_ms, @heard_every_ms), timer: nil}}
  end

  @impl true
  def handle_call({:subscribe, mirror}, _from, s) do
    s = if s.subscribers == %{}, do: follow(s), else: s
    s = if Map.has_key?(s.subscribers, mirror), do: s, else: put_in(s.subscribers[mirror], Process.monitor(mirror))
    vehicles = for {id, pid} <- s.vehicles, {:ok, view} <- [Vehicles.view(id)], do: {id, pid, view}
    {:reply, {:ok, %{node: node(), speedup: Clock.speedup(), vehicles: vehicles}}, s}
  end

  # What vehicles this node hears say, told on: several that waited
  # together go in one message (see the module doc).
  @impl true
  def handle_info({:dolphin, _topic, _event} = message, s) do
    {events, s} = gather(message, s, [], @events_at_once)

    case events do
      [] -> {:noreply, s}
      [event] -> {:noreply, tell(s, event)}
      events -> {:noreply, tell(s, {:batch, events})}
    end
  end

  def handle_info(:heard, %{subscribers: subs} = s) when subs == %{}, do: {:noreply, %{s | timer: nil}}

  def handle_info(:heard, s) do
    now = Clock.now_ms()
    # A restarted vehicle process has a new pid: the controllers learn it here.
    s = refresh_pids(s)

    # Read without a call to any vehicle: the views and the vehicles' heard cells.
    heard =
      for {id, _pid} <- s.vehicles, {:ok, view} <- [Vehicles.view(id)], into: %{} do
        last = Views.last_heard_ms(id)
        {id, {last && max(now - last, 0), view.link}}
      end

    tell(s, {:heard, heard})
    {:noreply, %{s | timer: Process.send_after(self(), :heard, s.heard_every_ms)}}
  end

  def handle_info({:DOWN, _ref, :process, pid, _reason}, s) do
    s = %{s | subscribers: Map.delete(s.subscribers, pid)}
    {:noreply, if(s.subscribers == %{}, do: unfollow(s), else: s)}
  end

  # This message's events for the controllers, and those of the notices
  # that wait behind it (at most `n` in all), in the order they came.
  defp gather(message, s, acc, n) do
    {told, s} = notice(message, s)
    acc = Enum.reverse(told, acc)

    # (Not even a look at the mailbox once the batch is full: a look that
    # takes nothing walks all of it.)
    if n > 1 do
      receive do
        {:dolphin, _topic, _event} = next -> gather(next, s, acc, n - 1)
      after
        0 -> {Enum.reverse(acc), s}
      end
    else
      {Enum.reverse(acc), s}
    end
  end

  # One notice of the local vehicles: the events it makes for the controllers.
  defp notice({:dolphin, :vehicles, {:vehicle_discovered, id}}, s) do
    case Vehicles.whereis_local(id) do
      nil -> {[], s}
      # Followed first, then read: a view put in between comes as a notice.
      pid ->
        s = watch(s, id, pid)
        {[{:discovered, id, pid, local_view(id)}], s}
    end
  end

  defp notice({:dolphin, :vehicles, {:vehicle_forgotten, id}}, s) do
    told =
      if Map.has_key?(s.vehicles, id) do
        PubSub.unsubscribe({:vehicle, id})
        [{:forgotten, id}]
      else
        []
      end

    {told, %{s | vehicles: Map.delete(s.vehicles, id)}}
  end

  defp notice({:dolphin, :vehicles, {event, id}}, s) when event in [:vehicle_lost, :vehicle_reconnected] do
    if Map.has_key?(s.vehicles, id), do: {[{if(event == :vehicle_lost, do: :lost, else: :reconnected), id}], s}, else: {[], s}
  end

  defp notice({:dolphin, {:vehicle, id}, {:view, view}}, s) do
    if Map.has_key?(s.vehicles, id), do: {[{:view, id, view}], s}, else: {[], s}
  end

  defp notice({:dolphin, _topic, _event}, s), do: {[], s}

  # The first subscriber: follow every local vehicle from now on.
  defp follow(s) do
    PubSub.subscribe(:vehicles)
    s = Enum.reduce(Vehicles.list(), s, fn id, s -> if pid = Vehicles.whereis_local(id), do: watch(s, id, pid), else: s end)
    %{s | timer: s.timer || Process.send_after(self(), :heard, s.heard_every_ms)}
  end

  # The last one went: nobody to tell, nothing to follow.
  defp unfollow(s) do
    PubSub.unsubscribe(:vehicles)

    for {id, _} <- s.vehicles, do: PubSub.unsubscribe({:vehicle, id})

    %{s | vehicles: %{}}
  end

  defp watch(s, id, pid) do
    unless Map.has_key?(s.vehicles, id), do: PubSub.subscribe({:vehicle, id})

    put_in(s.vehicles[id], pid)
  end

  defp refresh_pids(s) do
    Enum.reduce(s.vehicles, s, fn {id, pid}, s ->
      case Vehicles.whereis_local(id) do
        ^pid -> s
        nil -> s
        new ->
          tell(s, {:discovered, id, new, local_view(id)})
          put_in(s.vehicles[id], new)
      end
    end)
  end

  defp local_view(id) do
    case Vehicles.view(id) do
      {:ok, view} -> view
      _ -> %Vehicles.View{id: id}
    end
  end

  defp tell(s, event) do
    for {mirror, _ref} <- s.subscribers, do: send(mirror, {:dolphin_station, self(), event})
    s
  end
end
