defmodule Dolphin.Fleet do
  @moduledoc """
  The fleet: which vehicles exist, which are available, which a script has
  picked, which are busy running a task — and the allocation of a run's
  platform tasks to them.

  Vehicles come from a `Dolphin.Fleet.Source` (by default the MAVLink vehicles
  of `Dolphin.Vehicles`; `config :dolphin, vehicle_source: {module, arg}` or
  the `:source` option change it). A vehicle's state belongs to its source,
  and so do the events of its transitions (`vehicle_discovered`,
  `mode_changed`, `vehicle_lost`, ...: see `Dolphin.Vehicles.Views`); the
  fleet owns only who is picked, who is busy, the waiting picks and the
  reservations of runs. It keeps no copy of any vehicle: it reads the
  source's views (`Dolphin.Vehicles.View`) when it picks, serves waiting
  picks, reserves or lists, and follows the source's `:vehicles` events
  (discovered, lost, reconnected, forgotten, changed) to serve waiting picks
  again, plus a slow tick (1 s of clock time) while a pick waits on a region.
  It knows nothing of the engine: the engine calls it, never the other way
  round.

  ## Picking

      {:ok, set} = Dolphin.Fleet.pick(Dolphin.Fleet, self(), count: 2, type: :uav, timeout: 30_000)
      :ok = Dolphin.Fleet.release(Dolphin.Fleet, self(), set)

  A pick waits until `count` *available* vehicles (connected, picked by
  nobody, not busy) match every filter — `type` (a class or a list),
  `payload` (one or a list, all required), `region` (a `Dolphin.Geo.Area` the
  vehicle's position must be in), `id` (a system id or a list) — then marks
  them picked by `owner` and returns them. Waiting picks are served first
  come, first served: vehicles matching an earlier waiting pick are kept for
  it, so a large pick is not starved by a stream of small ones, while a pick
  that nobody earlier can use is served at once. After `timeout` (clock ms,
  default `:infinity`) it fails with a `Dolphin.Fleet.PickError` naming the
  requirement. The owner (a script's process) is monitored: when it ends, its
  vehicles are released.

  In a cluster of ground stations (`Dolphin.Cluster`) a pick is
  cluster-wide: before giving vehicles, the fleet claims them
  (`Dolphin.Fleet.Claims`, atomic across nodes), so two scripts on two nodes
  never get one vehicle, even when they pick at the same moment. A vehicle
  claimed on another node is left out of this fleet's picks until its claim
  is released there (the fleets are told) or that node goes down. On a node
  without distribution there are no claims to make.

  A vehicle lost while picked stays picked (it may come back); it is not
  given to new tasks while lost, and the task running on it fails. So does
  one forgotten while picked (`Dolphin.Vehicles.forget/1`), listed by
  `vehicles/1` as not connected until it is released.

  ## Allocation

  `reserve/5` (called by the engine when a run starts) gives each platform
  task of the run a vehicle among those the owner picked and that are not
  busy, using `Dolphin.Fleet.Allocation`, and marks them busy until
  `unreserve/2`.
  """

  use GenServer

  require Logger

  alias Dolphin.{Geo, PubSub, Events}
  alias Dolphin.Geo.Area
  alias Dolphin.Fleet.{Allocation, Claims, AllocationError, PickError, Source, VehicleSet}
  alias Dolphin.Vehicles.View

  @types [:uav, :ugv, :usv, :uuv, :other]
  @airframes View.airframes()
  @pick_keys [:count, :type, :airframe, :payload, :sensors, :region, :id, :timeout]
  # How often picks waiting on a region are checked again (clock ms), besides events.
  @region_tick 1_000

  @type fleet :: GenServer.server()

  # --- API ---

  @doc """
  Starts a fleet. Options: `:name` (required), `:source` (default
  `config :dolphin, vehicle_source:` or `{Dolphin.Fleet.MAVLinkSource, nil}`),
  `:events` (emit the events of picks, default true; vehicles' own events
  are their source's), `:claims` (claim picked vehicles cluster-wide, see
  `Dolphin.Fleet.Claims`; default true: a `Dolphin.Instance` other than
  the default, which is no cluster's, starts its fleet without).

  Each `Dolphin.Instance` starts one (`Dolphin.Fleet` in the default
  instance): the functions below without a fleet use the calling process's
  instance's.
  """
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts) do
    name = Keyword.fetch!(opts, :name)
    GenServer.start_link(__MODULE__, opts, name: name)
  end

  @doc false
  def child_spec(opts), do: %{id: Keyword.fetch!(opts, :name), start: {__MODULE__, :start_link, [opts]}}

  @doc "The fleet's vehicle source."
  @spec source(fleet()) :: Source.t()
  def source(fleet \\ here()) do
    case is_atom(fleet) && :persistent_term.get({__MODULE__, fleet}, nil) do
      source when is_tuple(source) -> source
      _ -> GenServer.call(fleet, :source)
    end
  end

  @doc "Changes the vehicle source (forgetting the vehicles of the old one); used by `mix dolphin.run --fake`."
  @spec set_source(fleet(), Source.t()) :: :ok
  def set_source(fleet \\ here(), {m, _} = source) when is_atom(m), do: GenServer.call(fleet, {:set_source, source})

  @doc """
  Every known vehicle with its status: `%{vehicle: View.t(), picked_by: pid | nil, busy: run_id | nil}`.
  A vehicle still picked that its source no longer knows (forgotten) is
  listed with a view of its id only, not connected.
  """
  @spec vehicles(fleet()) :: [%{vehicle: View.t(), picked_by: pid() | nil, busy: integer() | nil}]
  def vehicles(fleet \\ here()), do: GenServer.call(fleet, :vehicles)

  @doc "Picks vehicles for `owner` (see the module doc). Raises `ArgumentError` for an unknown or malformed option."
  @spec pick(fleet(), pid(), keyword()) :: {:ok, VehicleSet.t()} | {:error, PickError.t()}
  def pick(fleet, owner, opts) do
    req = requirement!(opts)
    GenServer.call(fleet, {:pick, owner, req}, :infinity)
  end

  @doc "Releases vehicles picked by `owner` (vehicles it did not pick are left alone)."
  @spec release(fleet(), pid(), VehicleSet.t() | [VehicleSet.t()]) :: :ok
  def release(fleet, owner, sets), do: GenServer.call(fleet, {:release, owner, VehicleSet.new(List.wrap(sets))})

  @doc """
  Releases every vehicle `owner` picked and drops its waiting picks (never
  answered), as when the owner ends — but now, so that the caller knows the
  `released` event has been given (a script that ends says so after it).
  """
  @spec release_all(fleet(), pid()) :: :ok
  def release_all(fleet, owner), do: GenServer.call(fleet, {:release_all, owner})

  @doc "The vehicles `owner` has picked."
  @spec picked(fleet(), pid()) :: VehicleSet.t()
  def picked(fleet, owner), do: GenServer.call(fleet, {:picked, owner})

  @doc "Sets the connection timeout (clock ms) of the vehicles `owner` picked and will pick."
  @spec set_connection_timeout(fleet(), pid(), pos_integer()) :: :ok
  def set_connection_timeout(fleet, owner, ms) when is_integer(ms) and ms > 0, do: GenServer.call(fleet, {:timeout, owner, ms})

  def set_connection_timeout(_fleet, _owner, ms),
    do: raise(ArgumentError, "a connection timeout is a positive number of milliseconds, got: #{inspect(ms)}")

  @doc false
  # Allocates vehicles to a run's platform tasks (Dolphin.Fleet.Allocation leaves)
  # and marks them busy for it. `inherit`: vehicles the run already holds.
  @spec reserve(fleet(), %{id: integer(), pid: pid()}, pid(), [Allocation.leaf()], [non_neg_integer()]) ::
          {:ok, %{integer() => non_neg_integer()}} | {:error, AllocationError.t()}
  def reserve(fleet, run, owner, leaves, inherit), do: GenServer.call(fleet, {:reserve, run, owner, leaves, inherit}, 60_000)

  @doc false
  @spec unreserve(fleet(), integer()) :: :ok
  def unreserve(fleet, run_id), do: GenServer.call(fleet, {:unreserve, run_id})

  @doc false
  # Checks and normalises pick options (caller mistakes raise here, in the caller).
  def requirement!(opts) when is_list(opts) do
    Enum.each(opts, fn
      {k, _} when k in @pick_keys -> :ok
      other -> raise ArgumentError, "unknown pick option #{inspect(other)}; options are #{inspect(@pick_keys)}"
    end)

    count = Keyword.get(opts, :count, 1)
    unless is_integer(count) and count > 0, do: raise(ArgumentError, "pick count must be a positive integer, got: #{inspect(count)}")

    type = Keyword.get(opts, :type)

    unless type == nil or Enum.all?(List.wrap(type), &(&1 in @types)),
      do: raise(ArgumentError, "pick type must be one of #{inspect(@types)} (or a list of them), got: #{inspect(type)}")

    airframe = Keyword.get(opts, :airframe)

    unless airframe == nil or Enum.all?(List.wrap(airframe), &(&1 in @airframes)),
      do: raise(ArgumentError, "pick airframe must be one of #{inspect(@airframes)} (or a list of them), got: #{inspect(airframe)}")

    payload = List.wrap(Keyword.get(opts, :payload))
    unless Enum.all?(payload, &is_atom/1), do: raise(ArgumentError, "pick payload must be an atom or a list of atoms, got: #{inspect(payload)}")

    sensors = List.wrap(Keyword.get(opts, :sensors))

    unless Enum.all?(sensors, &is_struct(&1, Dolphin.Sensors.Sensor)),
      do: raise(ArgumentError, "pick sensors must be sensors the script declared, named in place (sensors: [:smoke]), got: #{inspect(sensors)}")

    region = Keyword.get(opts, :region)
    unless region == nil or is_struct(region, Area), do: raise(ArgumentError, "pick region must be an area (area/2), got: #{inspect(region)}")

    id = Keyword.get(opts, :id)

    unless id == nil or Enum.all?(List.wrap(id), &Dolphin.Vehicles.Id.valid?/1),
      do: raise(ArgumentError, "pick id must be a vehicle id (a system id, or a name \"SYSID@NETWORK\") or a list of them, got: #{inspect(id)}")

    timeout = Keyword.get(opts, :timeout, :infinity)

    unless timeout == :infinity or (is_integer(timeout) and timeout >= 0),
      do: raise(ArgumentError, "pick timeout must be milliseconds or :infinity, got: #{inspect(timeout)}")

    %{count: count, type: type, airframe: airframe, payload: payload, sensors: sensors, region: region, id: id && List.wrap(id), timeout: timeout}
  end

  def requirement!(other), do: raise(ArgumentError, "pick options must be a keyword list, got: #{inspect(other)}")

  @doc false
  def describe(req) do
    [
      "#{req.count} vehicle#{if req.count > 1, do: "s"}",
      req.type && "type #{inspect(req.type)}",
      req[:airframe] && "airframe #{inspect(req.airframe)}",
      req.payload != [] && "payload #{inspect(req.payload)}",
      req[:sensors] not in [nil, []] && "sensors #{inspect(Enum.map(req.sensors, & &1.name))} heard",
      req.region && "in #{inspect(req.region)}",
      req.id && "id #{VehicleSet.format(req.id)}"
    ]
    |> Enum.filter(& &1)
    |> Enum.join(", ")
  end

  # --- server ---

  @impl true
  def init(opts) do
    name = Keyword.fetch!(opts, :name)
    source = Keyword.get_lazy(opts, :source, fn -> Application.get_env(:dolphin, :vehicle_source, {Dolphin.Fleet.MAVLinkSource, nil}) end)
    claims? = Keyword.get(opts, :claims, true)
    PubSub.subscribe(:vehicles)

    if claims? do
      # Claims released on other nodes, and nodes gone with their claims, may
      # make waiting picks servable.
      :ok = Claims.watch()
      :ok = :net_kernel.monitor_nodes(true)
    end

    s = %{
      name: name,
      claims?: claims?,
      source: nil,
      events: Keyword.get(opts, :events, true),
      # vehicle id => owner pid
      picked: %{},
      # pid => monitor ref (owners, waiting callers, runs)
      monitors: %{},
      timeouts: %{},
      # vehicle id => run id; run id => run pid
      busy: %{},
      runs: %{},
      waiters: [],
      # vehicles claimed by another node's pick (Dolphin.Fleet.Claims), as
      # learnt when claiming them failed; forgotten when claims are released
      claimed_elsewhere: MapSet.new(),
      region_tick: false,
      # A pre-flight check's stand-ins cannot have been heard sensing: it
      # takes a pick's sensors as heard (Dolphin.Check).
      assume_sensors?: Keyword.get(opts, :assume_sensors, false)
    }

    {:ok, use_source(s, source)}
  end

  defp use_source(s, source) do
    if is_atom(s.name), do: :persistent_term.put({__MODULE__, s.name}, source)
    %{s | source: source}
  end

  @impl true
  def terminate(_reason, s), do: if(is_atom(s.name), do: :persistent_term.erase({__MODULE__, s.name}))

  @impl true
  def handle_call(:source, _from, s), do: {:reply, s.source, s}
  def handle_call({:set_source, source}, _from, s), do: {:reply, :ok, s |> use_source(source) |> serve()}

  def handle_call(:vehicles, _from, s) do
    list = Enum.map(known(s), fn v -> %{vehicle: v, picked_by: s.picked[v.id], busy: s.busy[v.id]} end)
    {:reply, list, s}
  end

  def handle_call({:pick, owner, req}, {caller, _} = from, s) do
    s = s |> monitor(owner) |> monitor(caller)
    ref = make_ref()
    timer = if req.timeout != :infinity, do: Dolphin.Clock.send_after(self(), {:pick_timeout, ref}, req.timeout)
    waiter = %{ref: ref, from: from, caller: caller, owner: owner, req: req, timer: timer}
    {:noreply, serve(%{s | waiters: s.waiters ++ [waiter]})}
  end

  def handle_call({:release, owner, set}, _from, s), do: {:reply, :ok, s |> release_vehicles(owner, set.ids) |> serve()}
  def handle_call({:release_all, owner}, _from, s), do: {:reply, :ok, s |> drop_owner(owner) |> serve()}
  def handle_call({:picked, owner}, _from, s), do: {:reply, VehicleSet.new(picked_by(s, owner)), s}

  def handle_call({:timeout, owner, ms}, _from, s) do
    for id <- picked_by(s, owner), do: Source.set_timeout(s.source, id, ms)
    {:reply, :ok, %{monitor(s, owner) | timeouts: Map.put(s.timeouts, owner, ms)}}
  end

  def handle_call({:reserve, run, owner, leaves, inherit}, _from, s) do
    # The owner's vehicles that are free, plus those the run already holds
    # (a watch handler's task reuses its failed task's vehicles); those first.
    # Vehicles the source no longer knows cannot run anything.
    mine = Enum.sort(picked_by(s, owner))
    views = for id <- Enum.uniq(inherit ++ mine), {:ok, v} <- [Source.vehicle(s.source, id)], into: %{}, do: {id, v}
    usable = fn id -> Map.has_key?(views, id) and views[id].connected? and s.busy[id] in [nil, run.id] end
    pool = Enum.uniq(Enum.filter(inherit, usable) ++ Enum.filter(mine, &(usable.(&1) and s.busy[&1] == nil)))

    case Allocation.solve(leaves, Enum.map(pool, &views[&1])) do
      {:ok, assignment} ->
        busy = Enum.reduce(Map.values(assignment), s.busy, &Map.put(&2, &1, run.id))
        {:reply, {:ok, assignment}, %{monitor(s, run.pid) | busy: busy, runs: Map.put(s.runs, run.id, run.pid)}}

      {:error, _} = error ->
        {:reply, error, s}
    end
  end

  def handle_call({:unreserve, run_id}, _from, s), do: {:reply, :ok, s |> unreserve_run(run_id) |> serve()}

  # Whatever may make a waiting pick servable: a vehicle discovered,
  # reconnected, changed in what picks match on (see Dolphin.Fleet.Source).
  # A vehicle lost or forgotten only makes fewer vehicles available.
  @impl true
  def handle_info({:dolphin, :vehicles, {event, _id}}, s) when event in [:vehicle_discovered, :vehicle_reconnected, :vehicle_changed],
    do: {:noreply, serve(s)}

  def handle_info({Claims, :released, _ids}, s), do: {:noreply, serve(%{s | claimed_elsewhere: MapSet.new()})}
  def handle_info({:nodedown, _node}, s), do: {:noreply, serve(%{s | claimed_elsewhere: MapSet.new()})}

  def handle_info({:pick_timeout, ref}, s) do
    case Enum.split_with(s.waiters, &(&1.ref == ref)) do
      {[w], rest} ->
        error = pick_error(s, w.req)
        if s.events, do: Events.emit(:pick_failed, %{requirement: describe(w.req), reason: error.message})
        GenServer.reply(w.from, {:error, error})
        {:noreply, serve(%{s | waiters: rest})}

      {[], _} ->
        {:noreply, s}
    end
  end

  def handle_info(:region_tick, s) do
    s = serve(%{s | region_tick: false})
    {:noreply, s}
  end

  def handle_info({:DOWN, _ref, :process, pid, _reason}, s) do
    s = %{s | monitors: Map.delete(s.monitors, pid), timeouts: Map.delete(s.timeouts, pid)}
    # A run: its vehicles are no longer busy.
    s = Enum.reduce(for({run_id, ^pid} <- s.runs, do: run_id), s, &unreserve_run(&2, &1))
    {:noreply, s |> drop_owner(pid) |> serve()}
  end

  def handle_info(_other, s), do: {:noreply, s}

  # --- vehicles ---

  # The source's vehicles, and those picked that it no longer knows
  # (forgotten while picked: they stay picked, not connected).
  defp known(s) do
    views = Source.views(s.source)
    ids = MapSet.new(views, & &1.id)
    gone = for {id, _owner} <- s.picked, not MapSet.member?(ids, id), do: %View{id: id, connected?: false}
    Enum.sort_by(views ++ gone, & &1.id)
  end

  # --- picks ---

  # A waiting caller or owner gone: its waiting picks are dropped; an owner's vehicles are released.
  defp drop_owner(s, pid) do
    {gone, waiters} = Enum.split_with(s.waiters, &(&1.caller == pid or &1.owner == pid))
    for %{timer: timer} <- gone, timer != nil, do: Process.cancel_timer(timer)
    release_vehicles(%{s | waiters: waiters}, pid, picked_by(s, pid))
  end

  defp picked_by(s, owner), do: for({id, ^owner} <- s.picked, do: id)

  defp release_vehicles(s, _owner, []), do: s

  defp release_vehicles(s, owner, ids) do
    mine = Enum.filter(ids, &(s.picked[&1] == owner))
    if mine != [] and s.claims?, do: Claims.release(mine)
    if s.events and mine != [], do: Events.emit(:released, %{vehicles: Enum.sort(mine)})
    if mine != [], do: Source.released(s.source, mine)
    %{s | picked: Map.drop(s.picked, mine)}
  end

  defp unreserve_run(s, run_id) do
    busy = for {id, r} <- s.busy, r != run_id, into: %{}, do: {id, r}
    %{s | busy: busy, runs: Map.delete(s.runs, run_id)}
  end

  # Serves waiting picks in order, on the source's views read now; vehicles
  # an earlier waiter could use are kept for it (first come, first served).
  defp serve(%{waiters: []} = s), do: s

  defp serve(s) do
    available = for v <- Source.views(s.source), available?(s, v), do: v

    {s, waiters, _claimed} =
      Enum.reduce(s.waiters, {s, [], MapSet.new()}, fn w, {s, kept, claimed} ->
        case serve_waiter(s, w, available, claimed) do
          {:given, s} -> {s, kept, claimed}
          {:kept, s, matching} -> {s, [w | kept], Enum.reduce(matching, claimed, &MapSet.put(&2, &1.id))}
        end
      end)

    s = %{s | waiters: Enum.reverse(waiters)}

    if not s.region_tick and Enum.any?(s.waiters, & &1.req.region) do
      Dolphin.Clock.send_after(self(), :region_tick, @region_tick)
      %{s | region_tick: true}
    else
      s
    end
  end

  # Gives the waiter the first vehicles that match and that its cluster-wide
  # claim gets; those another node's pick holds are left out and the next
  # ones tried.
  defp serve_waiter(s, w, available, claimed) do
    # (What an earlier waiter of this round got, or learnt taken elsewhere, is no longer available.)
    matching = Enum.filter(available, &(matches?(requirement(s, w.req), &1) and not MapSet.member?(claimed, &1.id) and available?(s, &1)))

    with true <- length(matching) >= w.req.count,
         ids = matching |> Enum.take(w.req.count) |> Enum.map(& &1.id),
         :ok <- if(s.claims?, do: Claims.claim(ids, w.owner), else: :ok) do
      {:given, give(s, w, ids)}
    else
      false -> {:kept, s, matching}
      {:error, {:taken, taken}} -> serve_waiter(%{s | claimed_elsewhere: MapSet.union(s.claimed_elsewhere, MapSet.new(taken))}, w, available, claimed)
    end
  end

  defp give(s, w, ids) do
    if w.timer, do: Process.cancel_timer(w.timer)
    if ms = s.timeouts[w.owner], do: Enum.each(ids, &Source.set_timeout(s.source, &1, ms))
    if s.events, do: Events.emit(:picked, %{vehicles: ids, requirement: describe(w.req)})
    GenServer.reply(w.from, {:ok, VehicleSet.new(ids)})
    %{s | picked: Enum.reduce(ids, s.picked, &Map.put(&2, &1, w.owner))}
  end

  # Connected, and picked by nobody (here or, as far as this fleet learnt, on
  # another node), busy with no run.
  defp available?(s, %View{id: id} = v),
    do: v.connected? and s.picked[id] == nil and s.busy[id] == nil and not MapSet.member?(s.claimed_elsewhere, id)

  defp requirement(%{assume_sensors?: true}, req), do: %{req | sensors: []}
  defp requirement(_s, req), do: req

  defp matches?(req, %View{} = v) do
    (req.type == nil or v.type in List.wrap(req.type)) and (req.airframe == nil or v.airframe in List.wrap(req.airframe)) and Enum.all?(req.payload, &(&1 in v.payloads)) and
      Enum.all?(req.sensors, &Map.has_key?(v.sensors, &1.source)) and (req.region == nil or (v.position != nil and Geo.contains?(req.region, v.position))) and (req.id == nil or Enum.any?(req.id, &View.named?(v, &1)))
  end

  defp pick_error(s, req) do
    vehicles = known(s)

    known =
      Enum.map_join(vehicles, ", ", fn %View{id: id} = v ->
        status =
          cond do
            not v.connected? -> "lost"
            s.busy[id] -> "busy"
            s.picked[id] -> "picked"
            MapSet.member?(s.claimed_elsewhere, id) -> "picked on another node"
            true -> "available"
          end

        "#{id} (#{View.describe_kind(v)}#{if v.payloads != [], do: " " <> inspect(v.payloads), else: ""}, #{status})"
      end)

    n = Enum.count(vehicles, &(available?(s, &1) and matches?(requirement(s, req), &1)))

    %PickError{
      requirement: describe(req),
      message:
        "pick timed out after #{req.timeout} ms: wanted #{describe(req)}; #{n} available match; " <>
          "known vehicles: #{if known == "", do: "none", else: known}"
    }
  end

  defp monitor(s, pid) do
    case s.monitors do
      %{^pid => _} -> s
      _ -> %{s | monitors: Map.put(s.monitors, pid, Process.monitor(pid))}
    end
  end

  # The fleet of the calling process's instance.
  defp here, do: Dolphin.Instance.names().fleet
end
