defmodule Dolphin.Separation do
  @moduledoc """
  The live separation monitor: while missions fly, it keeps our vehicles
  apart by holding one of two that are about to come too close, and lets it
  go on once the way is clear.

  Every mission the MAVLink platform flies (`Dolphin.Mission.Platform`)
  registers its vehicle here once MISSION_START is accepted (`flying/2`),
  with the least separation of its run (`min_separation` in the script,
  else 20 m across and 10 m in height). On each view of a registered
  vehicle the monitor predicts, from its position and velocity and those of
  every other vehicle of the ground station in the air (registered or not),
  whether the two will come within the separation in the next
  8 seconds of clock time (`Dolphin.Separation.Prediction`). When they
  will:

    * the vehicle whose task started later holds (of two started within a
      second of each other, by `execute` or `|||`, the one the engine made
      later, so the choice does not depend on timing; its mission's process
      is sent `{:separation, :hold, info}`: it holds as its airframe holds,
      `Dolphin.Vehicles.Manoeuvres.hold_modes/1`, without failing its
      mission); a vehicle not flying one of our missions is never held, so
      the one that is holds;
    * but not in the other's way: when neither is held yet, the earlier
      one is a copter and, stopped (braking at 2.5 m/s²), would keep the
      two clearly further apart than the later one stopped — it is
      catching up with the other on its line, coming at it while it
      hovers, or would reach a crossing after it — the earlier one holds
      instead, and stays the one held while it is;
    * a held copter that the other still comes at once it has stopped (two
      vehicles on one line, or bound for one point) moves out of its way:
      twice the vertical separation up, or down when its fence's ceiling is
      too near (`{:separation, :aside, %{metres: m, ...}}`); the vehicle
      with the right of way is never held, so two never wait for each other;
    * `separation_hold` is emitted (`action` `hold`, then `aside`), with the
      pair, how far apart they are, the closest they would have come and in
      how many seconds.

  Two vehicles already closer than the separation but moving apart are
  left to go on: holding either would only keep them close.

  Each vehicle is judged where it is by now: its reported position moved on
  by its velocity for the time since the autopilot *made* the report, by
  the autopilot's own clock (`Dolphin.Separation.ReportClock`), not since
  the report reached the monitor, so a host or a link that holds reports
  back does not put a vehicle where it was.

  A held vehicle goes on (`{:separation, :clear, ...}`: its mission resumes
  where it was; a copter held before it left the ground, which ArduCopter
  disarms there, is armed and its mission started again) once, for a second of clock time, no vehicle in the air is
  closer than one and a half times the separation and none would come
  closer than that within the horizon were it to fly on as it was flying
  when held (a vehicle itself held, for this one or for another, whose
  task started later does not count: it waits for this one to go, so that
  of several held together the first goes first); `separation_clear` says
  so, with how long it was held. The hold counts in its task's time.

  Vehicles on the ground are not kept apart (a landing beside a parked
  vehicle is the pre-flight check's to judge); a submarine is kept apart
  only from submarines; vehicles the ground station does not hear are not
  seen at all.

  The monitor is a part of an instance (`Dolphin.Instance`), so runs of one
  ground station are kept apart from each other's vehicles too.
  """

  use GenServer

  alias Dolphin.{Clock, Events, Geo}
  alias Dolphin.Separation.{Prediction, ReportClock}
  alias Dolphin.Vehicles.{Manoeuvres, Views}

  @default_limits %{horizontal: 20.0, vertical: 10.0}
  # Seconds of clock time ahead the monitor looks.
  @horizon_s 8
  # A held vehicle goes on after this long (clock ms) with the way clear.
  @settle_ms 1_000
  # How often (clock ms) held vehicles are looked at when no view comes (a
  # braked vehicle's position may not change at all).
  @tick_ms 250
  # A held vehicle goes on only with this much more room than the least
  # separation: it starts from a stop, and the prediction is a straight line.
  @clear_margin 1.5
  # Tasks started within this long (clock ms) of each other started together.
  @together_ms 1_000
  # A held copter the other still comes at moves this many times the
  # vertical separation up (or down) out of its way.
  @aside_factor 2
  # Below this speed (m/s) a held vehicle has stopped.
  @stopped_ms 1.0
  # A held vehicle's braking (m/s²), for where it will stop: less than a
  # copter's, so that its stop is not placed short of where it comes.
  @brake_mps2 2.5
  # The earlier of two holds instead of the later only when that keeps
  # them this much further apart (m across).
  @better_by_m 2.0

  @doc "The separation kept when a script sets none: metres across and in height."
  @spec default_limits() :: %{horizontal: float(), vertical: float()}
  def default_limits, do: @default_limits

  @doc """
  Registers the calling process as the one flying a mission on vehicle `id`:
  it is sent `{:separation, :hold, %{vehicle: id, other: ..., ...}}`,
  `{:separation, :aside, %{metres: m, ...}}` and `{:separation, :clear,
  %{vehicle: id}}` until it exits. Options: `:started_at` (clock ms the mission's task started:
  the later of two holds), `:limits` (`%{horizontal: m, vertical: m}`).
  """
  @spec flying(Dolphin.Vehicles.Id.t(), keyword()) :: :ok
  def flying(id, opts \\ []) do
    started = {Keyword.get(opts, :started_at, Clock.now_ms()), Keyword.get(opts, :rank)}
    GenServer.call(server(), {:flying, id, self(), started, Keyword.get(opts, :limits) || @default_limits}, 15_000)
  end

  @doc "The vehicles held now: id => the vehicle it was first held for."
  @spec held() :: %{Dolphin.Vehicles.Id.t() => Dolphin.Vehicles.Id.t()}
  def held, do: GenServer.call(server(), :held)

  @doc false
  def start_link(opts), do: GenServer.start_link(__MODULE__, :ok, name: Keyword.fetch!(opts, :name))

  defp server, do: Dolphin.Instance.names().separation

  # --- the monitor ---------------------------------------------------------------

  defmodule Flying do
    @moduledoc false
    # One registered vehicle: who flies its mission, since when, its limits,
    # its latest view (and the clock time its position was reported,
    # `Dolphin.Separation.ReportClock`), and its hold, if held.
    defstruct [:id, :pid, :ref, :started_at, :rank, :limits, :view, :reported_at, held: nil]
  end

  @impl true
  def init(:ok) do
    # Safety first: on a host too busy for all its work, a hold does not wait
    # behind the rest (a thousand vehicles' views come here).
    Process.flag(:priority, :high)
    # A vehicle forgotten or lost leaves the station's vehicles read last (heard/1) at once.
    Dolphin.Vehicles.subscribe(:all)
    # `holding`: the ids of the held vehicles (looked at on every view and tick).
    # `clocks`: each vehicle's `ReportClock`, by id.
    {:ok, %{flying: %{}, holding: MapSet.new(), ticking: false, heard: nil, clocks: %{}}}
  end

  @impl true
  def handle_call({:flying, id, pid, {started_at, rank}, limits}, _from, s) do
    s = forget(s, id)
    Dolphin.Vehicles.subscribe(id)
    view = with {:ok, v} <- Views.get(id), do: v, else: (_ -> nil)
    reported_at = ReportClock.reported_at(s.clocks[id], view && view.boot_ms, Clock.now_ms())
    flying = %Flying{id: id, pid: pid, ref: Process.monitor(pid), started_at: started_at, rank: rank, limits: limits, view: view, reported_at: reported_at}
    # The station's vehicles are read anew for a new mission (what the table
    # holds now, not what it held up to a tick ago).
    {:reply, :ok, put_in(%{s | heard: nil}.flying[id], flying)}
  end

  def handle_call(:held, _from, s), do: {:reply, for({id, %{held: %{other: other}}} <- s.flying, into: %{}, do: {id, other}), s}

  @impl true
  def handle_info({:dolphin, {:vehicle, _id}, {:view, _view}} = message, s) do
    # The views queued behind this one too, in their order with the ends and
    # losses among them, and each vehicle judged once, on its latest: a large
    # fleet's views are not judged one stale view at a time.
    {s, seen} = Enum.reduce([message | queued_updates()], {s, MapSet.new()}, &update/2)
    s = Enum.reduce(Enum.sort(seen), s, fn id, s -> if match?(%Flying{view: %{}}, s.flying[id]), do: judge(s, id), else: s end)
    {:noreply, look_at_held(s)}
  end

  def handle_info(:tick, s), do: {:noreply, look_at_held(%{s | ticking: false})}

  def handle_info({:dolphin, :vehicles, {event, _id}} = message, s) when event in [:vehicle_forgotten, :vehicle_lost], do: {:noreply, elem(update(message, {s, MapSet.new()}), 0)}

  def handle_info({:DOWN, _ref, :process, _, _} = message, s), do: {:noreply, look_at_held(elem(update(message, {s, MapSet.new()}), 0))}

  def handle_info(_other, s), do: {:noreply, s}

  # What changes the vehicles the monitor follows, queued now.
  defp queued_updates do
    receive do
      {:dolphin, {:vehicle, _}, {:view, _}} = message -> [message | queued_updates()]
      {:dolphin, :vehicles, {event, _}} = message when event in [:vehicle_forgotten, :vehicle_lost] -> [message | queued_updates()]
      {:DOWN, _, :process, _, _} = message -> [message | queued_updates()]
    after
      0 -> []
    end
  end

  # One of them applied; `seen`: the registered vehicles a view came for.
  defp update({:dolphin, {:vehicle, id}, {:view, view}}, {s, seen}) do
    case s.flying do
      %{^id => f} ->
        now = Clock.now_ms()
        clock = ReportClock.observe(s.clocks[id], view.boot_ms, now)
        f = %{f | view: view, reported_at: ReportClock.reported_at(clock, view.boot_ms, now)}
        {%{s | flying: Map.put(s.flying, id, f), clocks: Map.put(s.clocks, id, clock)}, MapSet.put(seen, id)}

      _ ->
        {s, seen}
    end
  end

  # A vehicle forgotten is nowhere: its last view is no longer a place to keep
  # clear of, even while its mission's process has not yet gone.
  defp update({:dolphin, :vehicles, {:vehicle_forgotten, id}}, {s, seen}) do
    s = %{s | heard: nil, clocks: Map.delete(s.clocks, id)}
    {if(Map.has_key?(s.flying, id), do: put_in(s.flying[id].view, nil), else: s), seen}
  end

  # (Either leaves the station's vehicles read last at once.)
  defp update({:dolphin, :vehicles, {:vehicle_lost, _id}}, {s, seen}), do: {%{s | heard: nil}, seen}

  defp update({:DOWN, ref, :process, _, _}, {s, seen}) do
    case Enum.find(s.flying, fn {_, f} -> f.ref == ref end) do
      {id, _} -> {forget(s, id), MapSet.delete(seen, id)}
      nil -> {s, seen}
    end
  end

  defp forget(s, id) do
    case Map.pop(s.flying, id) do
      {nil, _} ->
        s

      {f, flying} ->
        Process.demonitor(f.ref, [:flush])
        Dolphin.PubSub.unsubscribe({:vehicle, id})
        %{s | flying: flying, holding: MapSet.delete(s.holding, id)}
    end
  end

  # --- judging a vehicle against the others ------------------------------------------

  defp judge(s, id) do
    now = Clock.now_ms()
    f = s.flying[id]

    if airborne?(f.view) do
      {others, s} = others(s, f)
      plane = Geo.tangent_plane(f.view.position)
      mine = motion(plane, f.view, now - f.reported_at)
      Enum.reduce(others, s, fn other, s -> judge_pair(s, id, mine, motion(plane, other.view, now - other.reported_at), other, now) end)
    else
      s
    end
  end

  defp judge_pair(s, id, mine, theirs, other, now) do
    f = s.flying[id]
    limits = limits(f, other)

    case Prediction.conflict(mine, theirs, limits, @horizon_s) do
      :clear ->
        s

      {:conflict, in_s, closest} ->
        {across, height} = Prediction.apart(mine, theirs)
        seen = %{distance: across, height: height, closest: closest, in_s: in_s, limits: limits}
        {holder, ahead, catching_up?} = holder(f, other, mine, theirs, limits)
        s = give_way_back(s, ahead, holder, now)

        cond do
          holder.held == nil -> hold(s, holder, ahead, catching_up?, seen, now)
          # Held, stopped, and the other still coming at it: a copter climbs (or
          # descends) out of its way, once a hold.
          not holder.held.aside and stopped?(holder.view) -> aside(s, holder, ahead, seen)
          true -> s
        end
    end
  end

  # Which of the two holds, and for which: the one whose task started later
  # (tasks started within a second of each other, by `execute` or `|||`:
  # the one written later), a vehicle flying none of ours never. But not a
  # vehicle the other is catching up with: stopped where it is going, it
  # would wait in the other's way (two on one line, the one behind faster:
  # held ahead, a copter was run into before it could climb aside). When
  # neither is held yet, the earlier one is a copter (it stops where it
  # brakes; a plane circles) and, stopped, keeps them clearly further apart
  # than the later one stopped, the earlier one holds (`catching_up?`), and
  # stays the one held while it is. That includes a later one hovering in
  # its way, or slowed to a stop at a turn (on ArduCopter SITL the one
  # ahead was below 1 m/s there): held, it would only climb aside, the race
  # that was lost; the earlier one waits for it to go on instead.
  # {holder, the other's id, catching_up?}.
  defp holder(%Flying{} = f, %Flying{} = o, mine, theirs, limits) do
    {later, earlier, later_motion, earlier_motion} = if later?(o, f), do: {o, f, theirs, mine}, else: {f, o, mine, theirs}

    cond do
      match?(%{other: id, catching_up?: true} when id == later.id, earlier.held) -> {earlier, later.id, true}
      later.held != nil or earlier.held != nil -> {later, earlier.id, false}
      earlier.view.airframe == :copter and
          closest_if_stopped(earlier_motion, later_motion, limits) > closest_if_stopped(later_motion, earlier_motion, limits) + @better_by_m ->
        {earlier, later.id, true}

      true ->
        {later, earlier.id, false}
    end
  end

  defp holder(%Flying{} = f, other, _mine, _theirs, _limits), do: {f, other.id, false}

  # How close (metres across, at most the limit: clear) two would come
  # within the horizon were the first to brake to a stop as it is held.
  defp closest_if_stopped({{n, e, u}, {vn, ve, vu}}, theirs, limits) do
    # It comes to rest v²/2a further on.
    k = :math.sqrt(vn * vn + ve * ve + vu * vu) / (2 * @brake_mps2)
    stopped = {{n + vn * k, e + ve * k, u + vu * k}, {0.0, 0.0, 0.0}}

    case Prediction.conflict(stopped, theirs, limits, @horizon_s) do
      :clear -> limits.horizontal
      {:conflict, _in_s, closest} -> closest
    end
  end

  defp later?(a, b) do
    if abs(a.started_at - b.started_at) >= @together_ms, do: a.started_at > b.started_at, else: {a.rank, a.id} > {b.rank, b.id}
  end

  # The one with the right of way held for the holder (held when the holder
  # flew none of our missions; it started a later one since): it goes on,
  # or the two would wait for each other.
  defp give_way_back(s, ahead, holder, now) do
    case s.flying[ahead] do
      %Flying{held: %{other: other}} = f when other == holder.id -> let_go(s, f, [holder], now)
      _ -> s
    end
  end

  defp hold(s, holder, other, catching_up?, seen, now) do
    send(holder.pid, {:separation, :hold, Map.merge(seen, %{vehicle: holder.id, other: other})})
    emit_hold(holder.id, other, seen, :hold)
    held = %{other: other, catching_up?: catching_up?, since: now, velocity: velocity(holder.view), height: holder.view.position.h, aside: false, clear_since: nil}
    s = %{s | holding: MapSet.put(s.holding, holder.id)}
    tick(put_in(s.flying[holder.id], %{holder | held: held}))
  end

  defp aside(s, holder, other, seen) do
    metres = seen.limits.vertical * @aside_factor
    send(holder.pid, {:separation, :aside, Map.merge(seen, %{vehicle: holder.id, other: other, metres: metres})})
    emit_hold(holder.id, other, seen, :aside)
    put_in(s.flying[holder.id].held.aside, true)
  end

  defp emit_hold(vehicle, other, seen, action) do
    Events.emit(:separation_hold, %{
      vehicle: vehicle,
      other: other,
      action: action,
      distance: Float.round(seen.distance * 1.0, 1),
      height: Float.round(seen.height * 1.0, 1),
      closest: Float.round(seen.closest * 1.0, 1),
      in_s: Float.round(seen.in_s * 1.0, 1),
      limit_m: seen.limits.horizontal,
      limit_height_m: seen.limits.vertical
    })
  end

  # --- letting held vehicles go ---------------------------------------------------

  defp look_at_held(s) do
    now = Clock.now_ms()
    s = Enum.reduce(Enum.sort(s.holding), s, fn id, s -> if s.flying[id].held, do: look_at(s, id, now), else: s end)
    if MapSet.size(s.holding) > 0, do: tick(s), else: s
  end

  defp look_at(s, id, now) do
    f = s.flying[id]
    held = f.held
    {others, s} = others(s, f)

    cond do
      not clear?(f, others, now) -> put_in(s.flying[id].held.clear_since, nil)
      held.clear_since == nil -> put_in(s.flying[id].held.clear_since, now)
      now - held.clear_since >= @settle_ms -> let_go(s, f, others, now)
      true -> s
    end
  end

  # No one closer than the separation, and no one it would come too close
  # to were it to fly on as it flew when held.
  defp clear?(%Flying{view: view}, _others, _now) when view == nil or view.position == nil, do: true

  # (One held that waits for this vehicle to go — held for it, or due to
  # give way to it, its task having started later — does not keep it held,
  # or two would wait for each other: two held for a third at one place, a
  # pad two take off from as a third lands on it, would stay held for ever.)
  defp clear?(f, others, now) do
    others = Enum.reject(others, &waits_for?(&1, f))
    plane = Geo.tangent_plane(f.view.position)
    # From where it is across, at the height it was held at (one that moved
    # aside goes back to it as it goes on).
    {{n, e, _}, _} = motion(plane, f.view, now - f.reported_at)
    going_on = {{n, e, f.held.height}, f.held.velocity}

    Enum.all?(others, fn other ->
      theirs = motion(plane, other.view, now - other.reported_at)
      limits = limits(f, other) |> Map.new(fn {k, m} -> {k, m * @clear_margin} end)
      Prediction.apart?(going_on, theirs, limits) and Prediction.conflict(going_on, theirs, limits, @horizon_s) == :clear
    end)
  end

  defp waits_for?(%Flying{held: %{other: other}} = o, f), do: other == f.id or later?(o, f)
  defp waits_for?(_other, _f), do: false

  defp let_go(s, f, others, now) do
    send(f.pid, {:separation, :clear, %{vehicle: f.id}})
    distance = with %{} = other <- Enum.find(others, &(&1.id == f.held.other)), do: distance(f, other), else: (_ -> nil)
    Events.emit(:separation_clear, %{vehicle: f.id, other: f.held.other, distance: distance, held_ms: now - f.held.since})
    put_in(%{s | holding: MapSet.delete(s.holding, f.id)}.flying[f.id].held, nil)
  end

  defp distance(f, other) do
    plane = Geo.tangent_plane(f.view.position)
    {across, _} = Prediction.apart(motion(plane, f.view, 0), motion(plane, other.view, 0))
    Float.round(across, 1)
  end

  defp tick(%{ticking: true} = s), do: s

  defp tick(s) do
    Process.send_after(self(), :tick, max(Clock.to_real_ms(@tick_ms), 1))
    %{s | ticking: true}
  end

  # --- what the monitor sees ------------------------------------------------------

  # Every other vehicle in the air that `f` is kept apart from: the
  # registered ones as their views came, the ground station's others as the
  # table has them now. One with no view (forgotten) is near no one. Only
  # those within reach are looked at (see "The station's vehicles"): a
  # fleet of a thousand is not a million pairs a view.
  defp others(s, %Flying{view: nil}), do: {[], s}

  defp others(s, f) do
    {heard, s} = heard(s)
    ids = nearby(heard, f)
    registered = for id <- ids, id != f.id, o = s.flying[id], o != nil, airborne?(o.view), same_medium?(f.view, o.view), do: o
    unregistered = for id <- ids, not Map.has_key?(s.flying, id), o = heard.airborne[id], o != nil, same_medium?(f.view, o.view), do: o
    {registered ++ unregistered, s}
  end

  # --- the station's vehicles -----------------------------------------------------
  #
  # Read from the views' table at most once a tick (the registered ones'
  # views come to the monitor itself): those in the air, and where every
  # placed vehicle was then, in cells of @cell_m metres. A vehicle's
  # candidates are the vehicles of the cells within its reach: the
  # separation (half as much again, for letting go), and how far the two
  # could close within the horizon — its speed (or the one it was held at)
  # and the fastest vehicle's — and how far a view is moved on for its age
  # and since the cells were made.

  @cell_m 100.0
  @metres_a_degree 111_000

  defp heard(%{heard: %{at: at} = heard} = s) do
    if Clock.now_ms() - at < @tick_ms, do: {heard, s}, else: heard(%{s | heard: nil})
  end

  defp heard(s) do
    now = Clock.now_ms()
    views = Views.all()
    placed = Enum.filter(views, &(&1.position != nil))
    # (Read after they came, at least a tick apart: the least difference learnt is a
    # little high, which errs towards a report made later, as before.)
    clocks = Enum.reduce(placed, s.clocks, fn view, clocks -> Map.put(clocks, view.id, ReportClock.observe(clocks[view.id], view.boot_ms, now)) end)
    airborne = for view <- placed, airborne?(view), into: %{}, do: {view.id, %{id: view.id, view: view, reported_at: ReportClock.reported_at(clocks[view.id], view.boot_ms, now)}}
    cells = Enum.group_by(placed, &cell(&1.position), & &1.id)
    fastest = Enum.reduce(placed, 0.0, &max(Dolphin.Vehicles.View.speed(&1), &2))
    widest = Enum.reduce(Map.values(s.flying), @default_limits.horizontal, &max(&1.limits.horizontal, &2))
    # How far a registered vehicle is moved on from where its last view (the
    # cells') put it, at most: its speed for the age of that view.
    drift = Enum.reduce(Map.values(s.flying), 0.0, fn o, most -> if o.view, do: max(most, Dolphin.Vehicles.View.speed(o.view) * max(now - o.reported_at, 0) / 1000), else: most end)
    heard = %{at: now, airborne: airborne, cells: cells, fastest: fastest, widest: widest, drift: drift}
    {heard, %{s | heard: heard, clocks: clocks}}
  end

  defp cell(%{lat: lat, lon: lon}), do: {floor(lat * @metres_a_degree / @cell_m), floor(lon * @metres_a_degree / @cell_m)}

  # The ids of the cells within `f`'s reach, in order (every placed vehicle
  # when the cells cannot say: near a pole or the 180th meridian).
  defp nearby(heard, %Flying{view: %{position: %{lat: lat, lon: lon} = at}} = f) do
    own = max(Dolphin.Vehicles.View.speed(f.view), if(f.held, do: speed(f.held.velocity), else: 0.0))
    # Its own view moved on for its age, the others' (heard.drift), and the
    # tick's worth of moving since the cells were made (twice: both may move).
    moved = Dolphin.Vehicles.View.speed(f.view) * max(Clock.now_ms() - f.reported_at, 0) / 1000 + heard.drift + 2 * @tick_ms / 1000 * heard.fastest
    reach = max(f.limits.horizontal, heard.widest) * @clear_margin + @horizon_s * (own + heard.fastest) + moved
    cos = :math.cos(abs(lat) * :math.pi() / 180)

    if cos < 0.05 or abs(lon) > 179 do
      heard.cells |> Map.values() |> List.flatten() |> Enum.sort()
    else
      # A cell is a little under @cell_m across north-south (a degree of
      # latitude is more than @metres_a_degree), and @cell_m * cos across east-west.
      rings_lat = ceil(reach / (@cell_m * 0.99)) + 1
      rings_lon = ceil(reach / (@cell_m * 0.99 * cos)) + 1
      {cn, ce} = cell(at)
      for(dn <- -rings_lat..rings_lat, de <- -rings_lon..rings_lon, id <- Map.get(heard.cells, {cn + dn, ce + de}, []), do: id) |> Enum.sort()
    end
  end

  defp nearby(_heard, _f), do: []

  defp speed({vn, ve, _vu}), do: :math.sqrt(vn * vn + ve * ve)
  defp speed(_), do: 0.0

  defp limits(%Flying{limits: mine}, %Flying{limits: theirs}), do: %{horizontal: max(mine.horizontal, theirs.horizontal), vertical: max(mine.vertical, theirs.vertical)}
  defp limits(%Flying{limits: mine}, _other), do: mine

  # In the air (an aircraft), or armed (a rover, boat or submarine: under
  # way), heard, and placed.
  defp airborne?(nil), do: false
  defp airborne?(%{position: nil}), do: false
  defp airborne?(%{connected?: false}), do: false
  defp airborne?(%{airframe: airframe} = view) when airframe in [:rover, :boat, :sub], do: view.armed?
  defp airborne?(view), do: Manoeuvres.in_air?(view)

  defp same_medium?(a, b), do: a.airframe == :sub == (b.airframe == :sub)

  defp stopped?(view), do: Dolphin.Vehicles.View.speed(view) < @stopped_ms

  defp velocity(%{velocity: {_, _, _} = v}), do: v
  defp velocity(_view), do: {0.0, 0.0, 0.0}

  # Where a vehicle is now, in the plane's frame, moved on by its velocity
  # for the `age_ms` since its view came, and its velocity.
  defp motion(plane, view, age_ms) do
    {vn, ve, vu} = velocity(view)
    {n, e} = Geo.to_tangent(plane, view.position.lat, view.position.lon)
    dt = max(age_ms, 0) / 1000
    {{n + vn * dt, e + ve * dt, view.position.h + vu * dt}, {vn, ve, vu}}
  end
end
