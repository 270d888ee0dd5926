defmodule Dolphin.Cluster.Mirror do
  @moduledoc """
  The controller side of a cluster of ground stations: makes the vehicles of
  the joined stations (`Dolphin.Cluster.Station` on other nodes) appear on
  this node as if they were its own, so that the fleet, the engine, the
  mission executor, the console and the live view work unchanged.

  For each remote vehicle it keeps which stations hear it (their vehicle
  process, latest view, how long ago they heard it, their link figures),
  chooses one (`Dolphin.Cluster.Choice`) and:

    * routes: it is the router of its vehicles in `Dolphin.Vehicles.Routes`,
      to which `Dolphin.Vehicles.whereis/1` falls back: the chosen station's
      vehicle process (a local vehicle of the same id always wins); it
      answers the calls `{:reroute, id, dead}` and `{:forget, id}` that the
      vehicles layer makes there;
    * puts each new view of the chosen station in `Dolphin.Vehicles.Views`,
      as a local vehicle does: `Dolphin.Vehicles.list/0` and `view/1` read
      it there, it is published on `{:vehicle, id}`, its transitions
      become this node's events (`mode_changed`, `vehicle_lost`, ...) and
      notices on `:vehicles` (`{:vehicle_discovered | :vehicle_lost |
      :vehicle_reconnected, id}`); a view it marks disconnected when no
      station hears the vehicle any more, and the view's deletion when the
      vehicle is forgotten (`{:vehicle_forgotten, id}`), are announced the
      same way;
    * fails over: when the chosen station's node goes down, or it stops
      hearing the vehicle (or tells nothing for 3 s of real time: its node
      hangs) while another station hears it, the route moves to
      the other (`station_changed` event) without any `vehicle_lost`, and
      the other's views are put once they show the vehicle later than the
      last one put (a station a little behind never takes it back); a
      vehicle no station hears any more is lost (at once when its last
      station's node goes down, else when the station's own vehicle times
      out), and reconnected when a station hears it again;
    * keeps two vehicles apart: once two stations' views of one id
      disagree (`Dolphin.Cluster.Choice.conflict/2`: two autopilots, two
      classes, two places), the vehicle stays the chosen station's (the
      first to hear it, unless it failed over since) and the other
      station's is another vehicle here, named by its id there and that
      station's node name, `"ID@NODE"` (`30` of `gs2@host` is `"30@gs2"`;
      by the whole node name, or numbered, if that is taken; see
      `Dolphin.Vehicles.Id`): a `vehicle_conflict` event says so, the
      new name is discovered as any vehicle is, and from then on
      everything that station tells of that id is of the new name (a third
      station that hears the same autopilot fails over with it). Most
      vehicles leave the factory as system id 1: two sites of one cluster
      may each fly theirs.

  It follows only the stations of the nodes joined with
  `Dolphin.Cluster.join/2` (`follow/2`); a node that only serves as a
  station mirrors nobody.
  """

  use GenServer
  require Logger

  alias Dolphin.{Clock, Events}
  alias Dolphin.Cluster.{Choice, Station}
  alias Dolphin.Vehicles.{Routes, View, Views}

  @reconnect_every_ms 1_000
  @stale_floor_ms 250
  # How long (real ms) a station switched to may stay behind before its view
  # is put anyway.
  @catch_up_real_ms 5_000
  # How long (real ms) a station may tell nothing before what it last told
  # is no longer believed.
  @silent_station_real_ms 3_000

  @doc false
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts, name: __MODULE__)

  @doc """
  Follows the stations of `node` from now on (and reconnects to it whenever
  it goes away); returns once one of them is subscribed to, or with
  `{:error, :no_station}` when none showed up within `timeout_ms`.
  """
  @spec follow(node(), non_neg_integer()) :: :ok | {:error, :no_station}
  def follow(node, timeout_ms \\ 5_000), do: GenServer.call(__MODULE__, {:follow, node, timeout_ms}, timeout_ms + 5_000)

  @doc "Stops following `node` (no more reconnection attempts; its vehicles stay until it leaves)."
  @spec unfollow(node()) :: :ok
  def unfollow(node), do: GenServer.call(__MODULE__, {:unfollow, node})

  @doc "The nodes joined (followed, and reconnected to when they go away)."
  @spec joined() :: [node()]
  def joined, do: GenServer.call(__MODULE__, :joined)

  @doc "The stations followed now: `%{station_pid => node}`."
  @spec stations() :: %{pid() => node()}
  def stations, do: GenServer.call(__MODULE__, :stations)

  @doc "Which stations hear each mirrored vehicle and which is chosen: `%{id => %{chosen: node, stations: [node], lost: boolean}}`."
  @spec routes() :: %{Dolphin.Vehicles.Id.t() => map()}
  def routes, do: GenServer.call(__MODULE__, :routes)

  @doc """
  A mirrored vehicle as each station that hears it calls it: `[{node, id
  there}]` (`[]` for a vehicle mirrored from nowhere). A cluster-wide claim
  holds these too (`Dolphin.Fleet.Claims`).
  """
  @spec heard_as(Dolphin.Vehicles.Id.t()) :: [{node(), Dolphin.Vehicles.Id.t()}]
  def heard_as(id), do: GenServer.call(__MODULE__, {:heard_as, id})

  # --- the process -------------------------------------------------------------

  @impl true
  def init(opts) do
    {:ok,
     %{
       enabled: false,
       pg_ref: nil,
       # Nodes joined (followed): reconnected to when they go away.
       joined: MapSet.new(),
       # Joins waiting for a station of their node: node => [{from, timer}].
       waiting: %{},
       # station pid => %{node, monitor, told_ms}: `told_ms`, when it last
       # told anything (real ms)
       stations: %{},
       # id => %{hearings: %{station => hearing}, chosen, lost, behind}:
       # `behind`, the view published last, while the station chosen since
       # has only older ones, and since when (real ms; see announce/4)
       vehicles: %{},
       # {station node, its id} => the id here, for the vehicles that are
       # not the same here (see split/5)
       names: %{},
       stale_ms: Keyword.get(opts, :stale_ms, Choice.stale_ms())
     }}
  end

  @impl true
  def handle_call({:follow, node, timeout_ms}, from, s) do
    s = enable(s)
    s = %{s | joined: MapSet.put(s.joined, node)}
    s = subscribe_all(s)

    if Enum.any?(s.stations, fn {_pid, st} -> st.node == node end) do
      {:reply, :ok, s}
    else
      timer = Process.send_after(self(), {:follow_timeout, node, from}, timeout_ms)
      {:noreply, update_in(s.waiting, &Map.update(&1, node, [{from, timer}], fn l -> [{from, timer} | l] end))}
    end
  end

  # Its stations stay followed while connected: they leave as any station does.
  def handle_call({:unfollow, node}, _from, s), do: {:reply, :ok, %{s | joined: MapSet.delete(s.joined, node)}}
  def handle_call(:joined, _from, s), do: {:reply, Enum.sort(s.joined), s}
  def handle_call(:stations, _from, s), do: {:reply, Map.new(s.stations, fn {pid, st} -> {pid, st.node} end), s}

  def handle_call({:heard_as, id}, _from, s) do
    heard = with %{^id => v} <- s.vehicles, do: for({station, h} <- v.hearings, do: {node(station), h.view.id}), else: (_ -> [])
    {:reply, Enum.sort(heard), s}
  end

  def handle_call(:routes, _from, s) do
    routes =
      Map.new(s.vehicles, fn {id, v} ->
        {id, %{chosen: v.chosen && node(v.chosen), stations: v.hearings |> Map.keys() |> Enum.map(&node/1) |> Enum.sort(), lost: v.lost}}
      end)

    {:reply, routes, s}
  end

  # Dolphin.Vehicles.Routes.reroute/2: a call to `dead` exited for want of
  # its node. The route now, or nil; the node's departure settled at once if
  # this process has not heard of it yet.
  def handle_call({:reroute, id, dead}, _from, s) do
    s = if node(dead) in Node.list(), do: s, else: node_gone(s, node(dead), "its node is not connected")

    case s.vehicles do
      %{^id => %{lost: false}} -> {:reply, Routes.get(id), s}
      _ -> {:reply, nil, s}
    end
  end

  # Dolphin.Vehicles.Routes.forget/1: the vehicle is forgotten here; it comes
  # back when a station tells of it anew (its discovery there, or the
  # station joined again).
  def handle_call({:forget, id}, _from, s) do
    if Map.has_key?(s.vehicles, id) do
      Routes.delete(id)

      # Deleting the view says it is forgotten.
      unless local?(id), do: Views.delete(id)
    end

    # (A name apart that is gone may be given again.)
    {:reply, :ok, %{s | vehicles: Map.delete(s.vehicles, id), names: Map.reject(s.names, fn {_key, other} -> other == id end)}}
  end

  @impl true
  def handle_info({ref, :join, :stations, pids}, %{pg_ref: ref} = s), do: {:noreply, Enum.reduce(pids, s, &subscribe(&2, &1))}
  def handle_info({ref, :leave, :stations, _pids}, %{pg_ref: ref} = s), do: {:noreply, s}

  def handle_info({:dolphin_station, station, event}, s) do
    if Map.has_key?(s.stations, station),
      do: {:noreply, station_event(put_in(s.stations[station].told_ms, real_ms()), station, event)},
      else: {:noreply, s}
  end

  def handle_info({:DOWN, _ref, :process, station, reason}, s) do
    case Map.fetch(s.stations, station) do
      {:ok, _} -> {:noreply, station_gone(s, station, down_words(reason))}
      :error -> {:noreply, s}
    end
  end

  def handle_info({:nodedown, node, _info}, s) do
    s = node_gone(s, node, "its node went down")
    if MapSet.member?(s.joined, node), do: Process.send_after(self(), {:reconnect, node}, @reconnect_every_ms)
    {:noreply, s}
  end

  def handle_info({:nodeup, _node, _info}, s), do: {:noreply, subscribe_all(s)}
  def handle_info({:catch_up, id}, s), do: {:noreply, catch_up(s, id)}

  # A joined node that went away is tried again until it answers; :pg then
  # tells of its station, and the station's vehicles come back.
  def handle_info({:reconnect, node}, s) do
    if MapSet.member?(s.joined, node) and node not in Node.list() do
      unless Node.connect(node) == true, do: Process.send_after(self(), {:reconnect, node}, @reconnect_every_ms)
    end

    {:noreply, s}
  end

  def handle_info({:follow_timeout, node, from}, s) do
    case Map.get(s.waiting, node, []) do
      [] ->
        {:noreply, s}

      waiters ->
        {mine, rest} = Enum.split_with(waiters, fn {f, _} -> f == from end)
        if mine != [], do: GenServer.reply(from, {:error, :no_station})
        {:noreply, %{s | waiting: if(rest == [], do: Map.delete(s.waiting, node), else: Map.put(s.waiting, node, rest))}}
    end
  end

  def handle_info(_other, s), do: {:noreply, s}

  # --- stations ------------------------------------------------------------------

  defp enable(%{enabled: true} = s), do: s

  defp enable(s) do
    {ref, _pids} = :pg.monitor(Dolphin.Cluster.scope(), :stations)
    :ok = :net_kernel.monitor_nodes(true, node_type: :visible)
    %{s | enabled: true, pg_ref: ref}
  end

  defp subscribe_all(%{enabled: false} = s), do: s
  defp subscribe_all(s), do: Enum.reduce(:pg.get_members(Dolphin.Cluster.scope(), :stations), s, &subscribe(&2, &1))

  # A station of a joined node, not yet followed: subscribed to, if it runs
  # at this node's speed-up. (Other nodes of the cluster are not followed
  # unless joined too.)
  defp subscribe(s, station) do
    if not MapSet.member?(s.joined, node(station)) or Map.has_key?(s.stations, station) or not s.enabled do
      s
    else
      case Station.subscribe(station, self()) do
        {:ok, %{speedup: k} = hello} ->
          if k == Clock.speedup() do
            s = %{s | stations: Map.put(s.stations, station, %{node: node(station), monitor: Process.monitor(station), told_ms: real_ms()})}
            Events.emit(:station_joined, %{station: node(station), heard: length(hello.vehicles)})
            s = Enum.reduce(hello.vehicles, s, fn {id, pid, view}, s -> told_of(s, station, id, pid, view) end)
            answer_waiters(s, node(station))
          else
            Logger.warning("not following the ground station on #{node(station)}: it runs at speed-up #{k}, this node at #{Clock.speedup()}")
            s
          end

        {:error, _} ->
          s
      end
    end
  end

  defp answer_waiters(s, node) do
    for {from, timer} <- Map.get(s.waiting, node, []) do
      Process.cancel_timer(timer)
      GenServer.reply(from, :ok)
    end

    %{s | waiting: Map.delete(s.waiting, node)}
  end

  defp node_gone(s, node, why) do
    s.stations
    |> Enum.filter(fn {_pid, st} -> st.node == node end)
    |> Enum.reduce(s, fn {station, _}, s -> station_gone(s, station, why) end)
  end

  # A station that left: every vehicle it heard is decided again without it.
  defp station_gone(s, station, why) do
    {st, stations} = Map.pop(s.stations, station)
    Process.demonitor(st.monitor, [:flush])
    Events.emit(:station_left, %{station: st.node, reason: why})
    s = %{s | stations: stations}

    Enum.reduce(s.vehicles, s, fn {id, v}, s ->
      if Map.has_key?(v.hearings, station) do
        decide(s, id, %{v | hearings: Map.delete(v.hearings, station)}, "#{st.node} left: #{why}")
      else
        s
      end
    end)
  end

  defp down_words(:noconnection), do: "its node is unreachable"
  defp down_words(reason), do: "its process ended (#{inspect(reason)})"

  defp station_event(s, station, {:batch, events}), do: Enum.reduce(events, s, &station_event(&2, station, &1))
  defp station_event(s, station, {:discovered, id, pid, view}), do: told_of(s, station, id, pid, view)
  defp station_event(s, station, {:view, id, view}), do: update_hearing(s, here(s, station, id), station, &%{&1 | view: view}, :view)

  defp station_event(s, station, {event, id}) when event in [:lost, :reconnected], do: update_hearing(s, here(s, station, id), station, & &1, event)

  defp station_event(s, station, {:forgotten, id}) do
    id = here(s, station, id)

    case s.vehicles do
      %{^id => v} -> decide(s, id, %{v | hearings: Map.delete(v.hearings, station)}, "forgotten by #{node(station)}")
      _ -> s
    end
  end

  defp station_event(s, station, {:heard, heard}) do
    Enum.reduce(heard, s, fn {id, {age, link}}, s ->
      update_hearing(s, here(s, station, id), station, &%{&1 | age_ms: age, link: link}, :heard)
    end)
  end

  defp station_event(s, _station, _other), do: s

  # The id here of what a station calls `id`, once it has told of it: the
  # name it was given apart, if the station is heard under it.
  defp here(s, station, id) do
    key = {node(station), id}

    with %{^key => other} <- s.names,
         %{^other => %{hearings: %{^station => _}}} <- s.vehicles do
      other
    else
      _ -> id
    end
  end

  # A vehicle a station tells of (its discovery there, or the station
  # followed anew): under the name it was given apart while it is the
  # vehicle of that name (the same autopilot, or close to where it was
  # last), else under its own id again (another vehicle behind it now:
  # the station restarted with another fleet, say), where it may be named
  # apart anew.
  defp told_of(s, station, id, pid, view) do
    key = {node(station), id}

    case s.names do
      %{^key => other} ->
        if here(s, station, id) == other or conflict_with(s, other, view) == :same,
          do: hear(s, other, station, pid, view),
          else: hear(%{s | names: Map.delete(s.names, key)}, id, station, pid, view)

      _ ->
        hear(s, id, station, pid, view)
    end
  end

  # A vehicle a station tells of for the first time (or with a new process).
  defp hear(s, id, station, pid, view) do
    v = Map.get(s.vehicles, id, %{hearings: %{}, chosen: nil, lost: nil, behind: nil})
    hearing = %{pid: pid, view: view, age_ms: nil, link: view.link}
    v = %{v | hearings: Map.put(v.hearings, station, hearing)}

    case conflict(v, station) do
      :same -> decide(s, id, v, "heard by #{node(station)}")
      {:conflict, why} -> split(s, id, v, station, why)
    end
  end

  defp update_hearing(s, id, station, fun, why) do
    with %{^id => v} <- s.vehicles, %{^station => h} <- v.hearings do
      v = %{v | hearings: Map.put(v.hearings, station, fun.(h))}

      case if(why == :view, do: conflict(v, station), else: :same) do
        :same ->
          s = decide(s, id, v, why)
          # A new view of the chosen station, once the choice is settled.
          if why == :view and s.vehicles[id].chosen == station and not s.vehicles[id].lost, do: publish_chosen(s, id), else: s

        {:conflict, reason} ->
          split(s, id, v, station, reason)
      end
    else
      _ -> s
    end
  end

  # The chosen station's latest view, unless it is still behind the one
  # published before the switch to it.
  defp publish_chosen(s, id) do
    v = s.vehicles[id]
    h = v.hearings[v.chosen]

    cond do
      v.behind == nil ->
        publish_view(id, h.pid, h.view)
        s

      View.newer?(h.view, v.behind.view) ->
        publish_view(id, h.pid, h.view)
        put_in(s.vehicles[id].behind, nil)

      true ->
        s
    end
  end

  # Whether the view of `station` is of another vehicle than the chosen
  # station's.
  defp conflict(%{chosen: chosen} = v, station) when chosen != nil and chosen != station do
    case v.hearings do
      %{^chosen => first} -> Choice.conflict(first.view, v.hearings[station].view)
      _ -> :same
    end
  end

  defp conflict(_v, _station), do: :same

  # Two stations whose views of one id are two vehicles: the chosen
  # station's keeps the id, the other's is another vehicle from now on —
  # one another station already told of under this station's id, if the
  # two are the same (a third station failing over with the second), else
  # a new one, "ID@NODE".
  defp split(s, id, v, station, why) do
    h = v.hearings[station]
    s = decide(s, id, %{v | hearings: Map.delete(v.hearings, station)}, "#{node(station)} hears another vehicle")
    theirs = h.view.id
    # (The station's own id here first: a station named apart may come to hear that vehicle.)
    known = Enum.uniq([theirs | same_named(s, theirs)]) -- [id]
    other = Enum.find(known, &(Map.has_key?(s.vehicles, &1) and conflict_with(s, &1, h.view) == :same)) || new_name(s, theirs, station)
    key = {node(station), theirs}
    s = %{s | names: if(other == theirs, do: Map.delete(s.names, key), else: Map.put(s.names, key, other))}
    s = hear(s, other, station, h.pid, h.view)
    # (Once the vehicle of that name is there to be looked up.)
    Events.emit(:vehicle_conflict, %{vehicle: id, stations: [node(v.chosen), node(station)], reason: why, other: other})
    Logger.warning("vehicle #{id}: #{node(v.chosen)} and #{node(station)} hear two different vehicles (#{why}); the one #{node(station)} hears is #{other} here")
    s
  end

  # The vehicles here named apart for what some station calls `theirs`.
  defp same_named(s, theirs), do: for({{_node, ^theirs}, other} <- s.names, Map.has_key?(s.vehicles, other), uniq: true, do: other)

  # Whether `view` is of another vehicle than `id` here: than its chosen
  # station's view, or the view last put for it when no station hears it.
  defp conflict_with(s, id, view) do
    case s.vehicles do
      %{^id => %{chosen: chosen, hearings: %{} = hearings}} when is_map_key(hearings, chosen) -> Choice.conflict(hearings[chosen].view, view)
      %{^id => _} -> if last = last_view(id), do: Choice.conflict(last, view), else: {:conflict, "nothing is known of it"}
      _ -> {:conflict, "nothing is known of it"}
    end
  end

  # "ID@NODE" by the node's name (`gs2` of `gs2@host`), else by the whole
  # node, else numbered: a name no vehicle here has.
  defp new_name(s, theirs, station) do
    short = station |> node() |> Atom.to_string() |> String.split("@") |> hd()
    named = ["#{theirs}@#{short}", "#{theirs}@#{node(station)}"] |> Stream.concat(Stream.map(Stream.iterate(2, &(&1 + 1)), &"#{theirs}@#{short}-#{&1}"))
    Enum.find(named, &(not Map.has_key?(s.vehicles, &1) and Dolphin.Vehicles.whereis_local(&1) == nil and &1 not in Map.values(s.names)))
  end

  # The choice made again for one vehicle, and what it changes published.
  defp decide(s, id, v, why) do
    hearings = v.hearings
    chosen = choose(s, hearings, v.chosen)
    lost = Choice.lost?(hearings)
    old = v

    cond do
      hearings == %{} and old.chosen == nil ->
        %{s | vehicles: Map.put(s.vehicles, id, v)}

      true ->
        v = announce(id, old, %{v | chosen: chosen || old.chosen, lost: lost}, why)
        %{s | vehicles: Map.put(s.vehicles, id, v)}
    end
  end

  # A vehicle only the station it has hears (most, and most of what stations
  # tell: four summaries of ages a second, a view each position): nothing
  # to choose, that station keeps it whatever its age (Choice.choose/3).
  defp choose(_s, hearings, chosen) when map_size(hearings) == 1 and is_map_key(hearings, chosen), do: chosen
  defp choose(s, hearings, chosen), do: Choice.choose(silent_as_stale(hearings, s), chosen, stale_ms: stale_ms(s))

  # Stale after stale_ms of clock time, but never under @stale_floor_ms of
  # real time: stations report ages that often, and a pause of this host or
  # of the network does not get shorter with the speed-up.
  defp stale_ms(s), do: max(s.stale_ms, round(@stale_floor_ms * Clock.speedup()))

  # A station tells how long ago it heard each vehicle every
  # Dolphin.Cluster.Station heard interval (250 ms of real time); one that
  # has told nothing for @silent_station_real_ms (its node hangs, or it is
  # starved) is not taken at the age it last told: its hearings count as
  # stale, so that another station takes over and none is switched to.
  defp silent_as_stale(hearings, s) do
    now = real_ms()

    Map.new(hearings, fn {station, h} ->
      case s.stations do
        %{^station => %{told_ms: told}} when now - told > @silent_station_real_ms -> {station, %{h | age_ms: stale_ms(s) + 1}}
        _ -> {station, h}
      end
    end)
  end

  # What the choice made for one vehicle changes, published; returns the
  # vehicle's record. A station switched to may be a little behind the one
  # it replaces (each station's views come as it folds the frames): its view
  # is published only once it shows the vehicle later than the view already
  # published (Dolphin.Vehicles.View.newer?/2), so that readers never see the
  # vehicle go back in time (back to a mode it has left: a mission's
  # executor would judge it left its mission).
  defp announce(id, old, v, why) do
    h = v.hearings[v.chosen]

    v =
      cond do
        old.chosen == nil ->
          # New here: the route, then the view, which says it is discovered.
          publish_view(id, h.pid, view_of(h, v.lost))
          v

        old.chosen != v.chosen ->
          Events.emit(:station_changed, %{vehicle: id, from: node(old.chosen), to: node(v.chosen), reason: reason_words(why)})
          switch_view(id, h, v)

        true ->
          v
      end

    cond do
      old.lost == false and v.lost ->
        # The view says it is lost (Dolphin.Vehicles.Views derives the news).
        last = if h && v.behind == nil, do: h.view, else: last_view(id)
        publish_view(id, Routes.get(id), last && %{last | connected?: false})
        %{v | behind: nil}

      old.lost == true and not v.lost ->
        publish_view(id, h.pid, h.view)
        %{v | behind: nil}

      true ->
        v
    end
  end

  # The route moves to the station switched to at once (commands go where
  # the vehicle is heard); its view waits, if it is behind the one published.
  defp switch_view(id, h, v) do
    published = if v.behind, do: v.behind.view, else: last_view(id)

    if v.lost or published == nil or View.newer?(h.view, published) do
      publish_view(id, h.pid, view_of(h, v.lost))
      %{v | behind: nil}
    else
      route(id, h.pid)
      Process.send_after(self(), {:catch_up, id}, @catch_up_real_ms)
      %{v | behind: %{view: published, since: real_ms()}}
    end
  end

  # A station that has not caught up within @catch_up_real_ms has its view
  # put all the same: its clock may not move (a vehicle at rest whose
  # position reports are all alike publishes no new view), and what it
  # says is the latest there is.
  defp catch_up(s, id) do
    with %{^id => %{behind: %{since: since}, lost: false} = v} <- s.vehicles,
         true <- real_ms() - since >= @catch_up_real_ms,
         %{} = h <- v.hearings[v.chosen] do
      publish_view(id, h.pid, h.view)
      put_in(s.vehicles[id].behind, nil)
    else
      _ -> s
    end
  end

  defp real_ms, do: System.monotonic_time(:millisecond)

  defp reason_words(why) when is_binary(why), do: why
  defp reason_words(:heard), do: "the station that had it stopped hearing it"
  defp reason_words(why), do: to_string(why)

  defp view_of(nil, _lost), do: nil
  defp view_of(h, true), do: %{h.view | connected?: false}
  defp view_of(h, false), do: h.view

  # The view last put for a vehicle, once no station hears it.
  defp last_view(id) do
    case Views.get(id) do
      {:ok, view} -> view
      {:error, _} -> nil
    end
  end

  # Every local publication of a remote vehicle's view goes through here:
  # the route first (whoever hears of the view finds where to send), then
  # Dolphin.Vehicles.Views, which keeps it for readers, publishes it and
  # turns its transitions into events as for a vehicle of this node's own —
  # unless a local vehicle of that id owns the view, or it is the view there.
  defp publish_view(_id, _pid, nil), do: :ok

  defp publish_view(id, pid, view) do
    route(id, pid)
    # Under the name it has here (a vehicle named apart is another id
    # there), and heard on no network of this node's: a station's network
    # names are its own, and another station's vehicle may be named here
    # by the very "SYSID@NETWORK" this one answers to there.
    view = %{view | id: id, network: nil}
    unless local?(id) or Views.get(id) == {:ok, view}, do: Views.put(view)
  end

  defp route(id, pid), do: if(Routes.get(id) != pid, do: Routes.put(id, pid))

  defp local?(id), do: Dolphin.Vehicles.whereis_local(id) != nil
end
