defmodule Dolphin.Vehicles.Vehicle do
  @moduledoc false
  # One process per discovered vehicle: folds its frames into a
  # Dolphin.Vehicles.State, puts its Dolphin.Vehicles.View in
  # Dolphin.Vehicles.Views when the view changed (which announces it, and the
  # loss or reconnection the view shows), watches for silence (lost /
  # reconnected) and asks the vehicle for the telemetry the ground station needs.
  # It holds nothing that the next telemetry does not restore, so a crash only
  # costs the state until the next frames.
  use GenServer, restart: :permanent

  alias Dolphin.{Clock, Events}
  alias Dolphin.Link.Connection
  alias Dolphin.MAVLink.Frame
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sensors.Readings
  alias Dolphin.Vehicles.{CommandProtocol, MissionProtocol, ParamList, ParamProtocol, Paths, Settings, State, View, Views}

  @lost_floor_real_ms 5_000
  @late_real_ms 100

  defstruct [
    :id,
    :sysid,
    :network,
    :paths,
    :judge_due,
    :state,
    :heard,
    :timeout_ms,
    :check_due_ms,
    :check_timer,
    :requests_left,
    :heard_real_ms,
    exact_timeout?: false,
    lost: false,
    view: nil,
    ops: %{},
    queued: %{},
    sensor_limits: %{},
    param_names: nil,
    param_count: nil
  ]

  # The process's state. `paths`: one path per link (and address) the vehicle
  # is heard on (Dolphin.Vehicles.Paths), the one it was discovered on in
  # use; `judge_due`: when they are judged next (real ms); `heard_real_ms`:
  # when its last fresh frame came (real ms). `state`: the
  # vehicle as its frames say (Dolphin.Vehicles.State); `heard`: the cell in
  # which its last frame's time is written for readers (Dolphin.Vehicles.Views.heard/2).
  # `check_due_ms`: when
  # the next silence check is due (clock ms): one that runs much later than
  # that does not judge (see :check_link); `check_timer`: its timer, made
  # anew when the timeout changes (a shorter one is checked at its own pace). `view`: the view last published
  # (Dolphin.Vehicles.View), nil before the first. `requests_left`: telemetry
  # requests to repeat until position telemetry comes. `ops`: operations
  # under way, by key (a command id, or :mission: one transfer at a time),
  # each %{pid, from, monitor, what}; `queued`: what waits for each key, a
  # queue of {module, request, opts, monitor}. `sensor_limits`: the sensor
  # sources watched, with their staleness limits (Dolphin.Vehicles.Settings.sensors/0).
  @type t :: %__MODULE__{
          id: Dolphin.Vehicles.Id.t(),
          sysid: byte(),
          network: String.t(),
          paths: Paths.t(),
          judge_due: integer(),
          state: State.t(),
          heard: :atomics.atomics_ref(),
          timeout_ms: pos_integer(),
          exact_timeout?: boolean(),
          check_due_ms: integer(),
          check_timer: reference(),
          requests_left: non_neg_integer(),
          lost: boolean(),
          view: View.t() | nil,
          ops: %{term() => map()},
          queued: %{term() => :queue.queue()},
          sensor_limits: %{Dolphin.Sensors.Sensor.source() => Readings.config()}
        }

  # Messages asked for by interval (µs of vehicle time) on top of the streams:
  # ArduPilot sends EXTENDED_SYS_STATE only when asked this way.
  @intervals [
    {33, 200_000},
    {1, 1_000_000},
    {147, 1_000_000},
    {42, 1_000_000},
    {245, 1_000_000},
    {242, 5_000_000}
  ]
  # Until position telemetry arrives, the requests are repeated this often, this many times.
  @request_every_ms 3_000
  @request_tries 5

  # The link is measured with TIMESYNC once a second of real time (a radio's
  # delay and loss do not change with the clock's speed-up), four times as
  # often at first so that the first commands and transfers already have
  # figures to go by; an answer later than this is a loss.
  @timesync_every_ms 1_000
  @timesync_first 8
  @timesync_stale_ms 2_000

  # The paths are judged this often (clock ms; at least every @judge_real_ms
  # of real time): a path in use that goes silent (1.5 s, see
  # Dolphin.Vehicles.Paths) is replaced within 2 s of clock time. A vehicle
  # heard on one path has none to change to: its path is judged once a
  # second (its silence shown, its autopilot asked for its id), a timer
  # that a fleet of thousands would otherwise run ten times a second each.
  @judge_every_ms 100
  @judge_real_ms 50
  @judge_alone_ms 1_000
  @judge_alone_real_ms 250

  def child_spec({id, _link, _opts} = args),
    do: %{id: {__MODULE__, id}, start: {__MODULE__, :start_link, [args]}, restart: :permanent}

  def start_link({id, _link, _opts} = args),
    do: GenServer.start_link(__MODULE__, args, name: {:via, Registry, {Dolphin.Instance.names().registry, {:vehicle, id}}})

  @impl true
  def init({id, link, opts}) do
    sysid = Dolphin.Vehicles.Id.sysid(id)
    # Command protocols are linked to this process: their exits come as messages.
    Process.flag(:trap_exit, true)
    # A timeout set for this vehicle (Dolphin.Vehicles.set_timeout/2) survives
    # restarts, and is kept exactly (lost_after_ms/2 is for the default's).
    set = Settings.timeout(id, Keyword.get(opts, :timeout_ms))
    timeout = set || Application.get_env(:dolphin, :vehicle_timeout_ms, 20_000)

    send(self(), :request_telemetry)
    send(self(), {:timesync, 0})
    check_timer = Clock.send_after(self(), :check_link, check_period(timeout))
    now = Clock.now_ms()
    real = real_ms()

    heard = Views.heard_cell(id)
    Views.heard(heard, now)
    # A restarted process: the vehicle's unique id, which its view kept,
    # stays the one new paths are compared with.
    last_view = with {:ok, view} <- Views.get(id), do: view, else: (_ -> nil)
    uid = last_view && last_view.uid
    paths = Paths.new(link, now, real)
    paths = if uid, do: Paths.identified(paths, link, uid), else: paths
    Process.send_after(self(), :judge_paths, judge_period(paths))

    {:ok,
     %__MODULE__{
       id: id,
       sysid: sysid,
       network: Dolphin.Vehicles.Id.network(link),
       heard: heard,
       paths: paths,
       view: last_view,
       judge_due: real + judge_period(paths),
       # Seen now (it was just heard, or its process restarted): silence from
       # here on makes it lost.
       state: State.watch_sensors(%{put_in(State.new(id).link.last_seen_ms, now) | uid: uid}, Readings.watch(Settings.sensors())),
       sensor_limits: Settings.sensors(),
       timeout_ms: timeout,
       exact_timeout?: set != nil,
       check_due_ms: now + check_period(timeout),
       check_timer: check_timer,
       heard_real_ms: real,
       requests_left: @request_tries
     }}
  end

  @impl true
  def handle_cast({:frame, frame, link}, s) do
    now = Clock.now_ms()
    real = real_ms()
    {verdict, paths} = Paths.heard(s.paths, link, frame, now, real)
    s = %{s | paths: identify(paths, link, frame)}
    # Heard again: the view that says so is the one with this frame in it
    # (published below), so that whoever is told reads what was heard.
    s = if s.lost and verdict != :unidentified, do: reconnected(s), else: s

    case verdict do
      # A path not known to be this vehicle's (pending, or another vehicle
      # with the same system id): nothing of it is the vehicle's.
      :unidentified ->
        {:noreply, s}

      # A copy of a frame already heard on another path: it counted for its
      # path's figures, and goes no further (the state and the protocols had it).
      :duplicate ->
        {:noreply, publish(s, %{s.state | link_quality: Paths.quality(s.paths)})}

      :fresh ->
        Views.heard(s.heard, now)
        s = %{s | heard_real_ms: real}
        old = s.state
        s = publish(s, %{State.apply(old, frame, now) | link_quality: Paths.quality(s.paths)})
        arm_staleness(s, Readings.fresh(old.sensors, s.state.sensors))
        route_to_op(s, frame)
        s = param_count(s, frame)

        # Position telemetry flowing means the requests were heard.
        requests_left = if match?(%M.GlobalPositionInt{}, frame.message), do: 0, else: s.requests_left
        {:noreply, %{s | requests_left: requests_left}}
    end
  end

  # Several frames a link took in one wake-up: each as if it came alone.
  def handle_cast({:frames, frames}, s) do
    {:noreply, Enum.reduce(frames, s, fn {frame, link}, s -> elem(handle_cast({:frame, frame, link}, s), 1) end)}
  end

  def handle_cast(:settings_changed, s), do: {:noreply, publish_view(s)}

  def handle_cast(:sensors_changed, s) do
    limits = Settings.sensors()
    s = publish(%{s | sensor_limits: limits}, State.watch_sensors(s.state, Readings.watch(limits)))
    # The readings held already are judged by the limits declared now (a
    # limit already passed marks its reading at once).
    now = Clock.now_ms()

    for {source, %{at: at}} <- s.state.sensors,
        %{stale_after: ms_list} <- [Map.get(limits, source)],
        ms <- ms_list,
        do: Clock.send_after(self(), {:sensor_stale, source, at, ms}, max(at + ms - now, 0))

    {:noreply, s}
  end

  def handle_cast({:send, message}, s) do
    send_message(s, message)
    {:noreply, s}
  end

  @impl true
  def handle_call(:state, _from, s), do: {:reply, %{s.state | seqs: %{}}, s}
  def handle_call(:view, _from, s), do: {:reply, s.view || view(s), s}

  def handle_call(:paths, _from, s), do: {:reply, Paths.list(s.paths), s}
  # The names of the whole parameter list the autopilot gave last, while its
  # values still say that list's count (another count: the list changed).
  def handle_call(:param_names, _from, %{param_names: {count, names}, param_count: count} = s), do: {:reply, names, s}
  def handle_call(:param_names, _from, s), do: {:reply, nil, s}

  def handle_call({:set_timeout, ms}, _from, s) do
    Process.cancel_timer(s.check_timer)
    period = check_period(ms)
    check_timer = Clock.send_after(self(), :check_link, period)
    {:reply, :ok, %{s | timeout_ms: ms, exact_timeout?: true, check_timer: check_timer, check_due_ms: Clock.now_ms() + period}}
  end

  # One command of an id at a time (a COMMAND_ACK names only the command id),
  # one mission transfer at a time; the rest wait their turn. The protocol
  # replies to the caller.
  def handle_call({:command, request, opts}, from, s), do: {:noreply, run_op(s, request.command, CommandProtocol, request, opts, from)}
  def handle_call({:mission, request, opts}, from, s), do: {:noreply, run_op(s, :mission, MissionProtocol, request, opts, from)}
  def handle_call({:param, request, opts}, from, s), do: {:noreply, run_op(s, {:param, request.name}, ParamProtocol, request, opts, from)}
  def handle_call({:param_list, opts}, from, s), do: {:noreply, run_op(s, :param_list, ParamList, %{}, opts, from)}

  # The name goes with the process, not a moment later when the registry
  # hears of the exit: once Dolphin.Vehicles.forget/1 has stopped a vehicle,
  # whereis/1 no longer gives it, and a vehicle heard again at once is
  # discovered anew rather than cast to a dead process.
  @impl true
  def terminate(_reason, s), do: Registry.unregister(Dolphin.Instance.names().registry, {:vehicle, s.id})

  @impl true
  def handle_info(:request_telemetry, %{requests_left: 0} = s), do: {:noreply, s}

  # A reading that outlived a staleness limit with no newer one: the view
  # says so at that moment, so that a condition on it is judged then, even
  # when nothing else of the vehicle changes.
  def handle_info({:sensor_stale, source, at, ms}, s) do
    case Readings.stale(s.state.sensors, source, at, ms) do
      :unchanged -> {:noreply, s}
      sensors -> {:noreply, publish(s, %{s.state | sensors: sensors})}
    end
  end

  # The names of a whole parameter list the autopilot gave (ParamList), for
  # telling a name it has not from one whose answer was lost.
  def handle_info({:param_names, count, names}, s), do: {:noreply, %{s | param_names: {count, names}}}

  def handle_info(:request_telemetry, s) do
    s = request_telemetry(s)
    Clock.send_after(self(), :request_telemetry, @request_every_ms)
    {:noreply, %{s | requests_left: s.requests_left - 1}}
  end

  def handle_info({:EXIT, pid, reason}, s) do
    case Enum.find(s.ops, fn {_key, op} -> op.pid == pid end) do
      {key, op} ->
        # A protocol that crashed (or was stopped) did not answer its caller.
        if reason != :normal and op.from, do: GenServer.reply(op.from, {:error, crashed(s, op.what, reason)})
        if op.monitor, do: Process.demonitor(op.monitor, [:flush])
        {:noreply, next_op(%{s | ops: Map.delete(s.ops, key)}, key)}

      nil ->
        {:noreply, s}
    end
  end

  # A caller that went away: what it queued is dropped, what runs for it is stopped.
  def handle_info({:DOWN, monitor, :process, _pid, _reason}, s) do
    queued = Map.new(s.queued, fn {key, queue} -> {key, :queue.filter(fn {_m, _r, _o, mon} -> mon != monitor end, queue)} end)

    for {_key, %{monitor: ^monitor, pid: pid}} <- s.ops, do: Process.exit(pid, :caller_gone)
    {:noreply, %{s | queued: queued}}
  end

  # Each path is measured on its own: a TIMESYNC goes out on every path,
  # stamped so that its answer is matched to its path.
  def handle_info({:timesync, n}, s) do
    now = real_ms()
    {requests, paths} = s.paths |> Paths.measure(now, @timesync_stale_ms) |> Paths.timesync(System.os_time(:nanosecond), now)
    for {via, ts1} <- requests, do: Connection.send_via(via, s.sysid, %M.Timesync{tc1: 0, ts1: ts1})
    Process.send_after(self(), {:timesync, n + 1}, if(n < @timesync_first, do: div(@timesync_every_ms, 4), else: @timesync_every_ms))
    {:noreply, publish(%{s | paths: paths}, %{s.state | link_quality: Paths.quality(paths)})}
  end

  # As with silence (:check_link), a judging that runs more than a period late
  # does not judge: the frames of the while this host was held up may still
  # wait in the mailbox, and a path would look silent for want of reading them.
  def handle_info(:judge_paths, s) do
    period = judge_period(s.paths)
    Process.send_after(self(), :judge_paths, period)
    now = real_ms()
    on_time? = now - s.judge_due <= period
    s = %{s | judge_due: now + period}

    s = identity_checks(s, now)

    if on_time? do
      {paths, change} = Paths.judge(s.paths, Clock.now_ms(), now)
      s = %{s | paths: paths}

      # Judging moves no figures: only a new path in use brings other ones.
      if change do
        path_changed(s, change)
        {:noreply, publish(s, %{s.state | link_quality: Paths.quality(paths)})}
      else
        {:noreply, s}
      end
    else
      {:noreply, s}
    end
  end

  # Silence is judged only by a check that runs on time. One that runs more than
  # a period late (and more than 100 ms of real time: at a high speed-up a
  # period is a few real milliseconds, less than a loaded host's scheduler
  # makes any timer late) means this machine held the ground station up (a
  # loaded host, a paused VM): the vehicle's frames of that while may still
  # wait in the link's socket and mailbox, so the silence may be ours, not the
  # vehicle's. The next check, once they are read, judges.
  def handle_info(:check_link, s) do
    # A check of the timeout before the last set_timeout/2, already sent when
    # it was cancelled: the new timer's check is still to come.
    if is_integer(Process.read_timer(s.check_timer)), do: {:noreply, s}, else: check_link(s)
  end

  defp check_link(s) do
    period = check_period(s.timeout_ms)
    s = %{s | check_timer: Clock.send_after(self(), :check_link, period)}
    # The vehicle's heard cell, made anew if it was deleted meanwhile (the
    # vehicle forgotten while this process lived on).
    s = %{s | heard: Views.heard_cell(s.id)}
    now = Clock.now_ms()
    on_time? = now - s.check_due_ms <= max(period, @late_real_ms * Clock.speedup())
    # Paths silent for as long as the vehicle timeout (a vehicle that came
    # back from another address) are forgotten.
    s = %{s | check_due_ms: now + period, paths: Paths.forget_silent(s.paths, now, s.timeout_ms)}
    last = s.state.link.last_seen_ms

    # A frame already in this process's mailbox, behind the check, ends the
    # silence: the next check judges once it is read.
    if on_time? and not s.lost and last != nil and silent?(s, now - last, real_ms() - s.heard_real_ms) and not frame_waiting?() do
      # The view first: whoever hears of the loss finds the view saying so.
      {:noreply, publish_view(%{s | lost: true})}
    else
      {:noreply, s}
    end
  end

  defp frame_waiting? do
    case Process.info(self(), :message_queue_len) do
      {:message_queue_len, 0} -> false
      _ -> self() |> Process.info(:messages) |> elem(1) |> Enum.any?(&match?({:"$gen_cast", {:frame, _, _}}, &1))
    end
  end

  defp real_ms, do: System.monotonic_time(:millisecond)

  defp arm_staleness(_s, []), do: :ok

  defp arm_staleness(s, fresh) do
    for {source, at} <- fresh, %{stale_after: limits} <- [Map.get(s.sensor_limits, source)], ms <- limits, do: Clock.send_after(self(), {:sensor_stale, source, at, ms}, ms)

    :ok
  end

  @doc """
  The silence, in clock time, after which a vehicle with the default
  timeout `timeout_ms` (clock time; 20 s, or `config :dolphin,
  vehicle_timeout_ms:`) is lost at speed-up `speedup`: that timeout, and at
  a speed-up never less than min(timeout, 5 s) of real time (a timeout set
  for a vehicle, `Dolphin.Vehicles.set_timeout/2`, is kept exactly). A sped-up
  vehicle is a simulation, and a simulation on a busy host falls behind its
  speed-up: ArduCopter SITL at 15x beside two busy loops went 1.3 s of real
  time without a frame (20 s of clock time), and one of six at 10x, on two
  cores loaded four times over, 3.5 s (its own clock stood still meanwhile).
  At 1x the floor is the timeout itself. The floor is measured in real
  time: when the speed-up changes during a silence (the clock follows a
  SITL vehicle's pace), the silence is judged against the timeout in clock
  time and the floor in real time, not against this figure at the new speed-up.

      iex> Dolphin.Vehicles.Vehicle.lost_after_ms(20_000, 1)
      20000
      iex> Dolphin.Vehicles.Vehicle.lost_after_ms(20_000, 15)
      75000
      iex> Dolphin.Vehicles.Vehicle.lost_after_ms(2_000, 10)
      20000
  """
  @spec lost_after_ms(pos_integer(), number()) :: pos_integer()
  def lost_after_ms(timeout_ms, speedup), do: max(timeout_ms, round(min(timeout_ms, @lost_floor_real_ms) * speedup))

  # A timeout set for the vehicle is what its setter asked for, to the letter.
  # The default's floor is real time, measured as such: a silence that began
  # at a higher speed-up (the clock slowed since to a fallen-behind SITL's
  # pace) is not judged by the floor of the lower one, which its clock time,
  # run up at the higher, would already pass.
  defp silent?(%{exact_timeout?: true, timeout_ms: ms}, clock_ms, _real_ms), do: clock_ms > ms
  defp silent?(s, clock_ms, real_ms), do: clock_ms > s.timeout_ms and real_ms > min(s.timeout_ms, @lost_floor_real_ms)

  # What the autopilot heard on a path says it is: its unique id.
  defp identify(paths, via, %Frame{compid: 1, message: %M.AutopilotVersion{} = version}), do: Paths.identified(paths, via, State.unique_id(version))
  defp identify(paths, _via, _frame), do: paths

  # The path in use until the vehicle's unique id is known, and each new
  # path: asked for their autopilot's (MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
  # which ArduPilot answers with AUTOPILOT_VERSION); new paths then decided
  # (Dolphin.Vehicles.Paths, "Another vehicle with the same system id").
  defp identity_checks(s, real) do
    now = Clock.now_ms()
    {asks, paths} = Paths.identity_asks(s.paths, now, real)
    for via <- asks, do: Connection.send_via(via, s.sysid, %M.CommandLong{target_system: s.sysid, target_component: 1, command: 520, param1: 1.0})
    {paths, decisions} = Paths.settle(paths, now, real)

    # Another vehicle with this system id: the path is that vehicle's.
    for {via, {:refused, uid, own}} <- decisions do
      other = Dolphin.Vehicles.heard_elsewhere(s.sysid, via, uid)
      Events.emit(:system_id_shared, %{vehicle: s.id, path: Paths.via_text(via), uid: uid, vehicle_uid: own, other: other})
    end

    %{s | paths: paths}
  end

  defp judge_period(paths) do
    if Paths.several?(paths),
      do: max(Clock.to_real_ms(@judge_every_ms), @judge_real_ms),
      else: max(Clock.to_real_ms(@judge_alone_ms), @judge_alone_real_ms)
  end

  # Everything to the vehicle goes on the path in use at the time of sending.
  defp send_message(s, message), do: Connection.send_via(Paths.in_use(s.paths), s.sysid, message)

  defp path_changed(s, {from, to, reason}),
    do: Events.emit(:path_changed, %{vehicle: s.id, from: Paths.via_text(from), to: Paths.via_text(to), reason: reason})

  # The new state, and its view when it changed: only a change of a public
  # field can change the view (link counters change with every frame).
  defp publish(s, new) do
    # A vehicle heard again is published even when what it said is unchanged.
    told_lost? = s.view != nil and s.view.connected? == s.lost

    case State.changes(s.state, new) do
      [] when not told_lost? -> %{s | state: new}
      _changes -> publish_view(%{s | state: new})
    end
  end

  # The view, to Dolphin.Vehicles.Views (which tells its subscribers and
  # emits its transitions), when it is not the one they have.
  # Not before the vehicle's type is known (its autopilot's HEARTBEAT): a
  # vehicle is announced once, with its type, and a restarted process does
  # not put a blank view over the one it had — only whether the vehicle is
  # heard changes in it until then.
  defp publish_view(%{state: %{type: nil}, view: nil} = s), do: s

  defp publish_view(%{state: %{type: nil}, view: last} = s) do
    case %{last | connected?: not s.lost} do
      ^last ->
        s

      view ->
        Views.put(view)
        %{s | view: view}
    end
  end

  defp publish_view(s) do
    case view(s) do
      same when same == s.view ->
        s

      view ->
        Views.put(view)
        %{s | view: view}
    end
  end

  # Payloads given to the vehicle (Settings: a fleet file's, SITL's camera)
  # and configured ones (`config :dolphin, vehicle_payloads:`).
  defp view(s) do
    configured = Application.get_env(:dolphin, :vehicle_payloads, %{}) |> Map.get(s.id, []) |> List.wrap()
    %{View.of(s.state, s.lost, Settings.payloads(s.id) ++ configured) | network: s.network}
  end

  # Heard again after a silence: no longer lost (the next view published
  # says so), and telemetry asked for again (the vehicle may have rebooted
  # and forgotten the rates).
  defp reconnected(s) do
    if s.requests_left == 0, do: send(self(), :request_telemetry)
    %{s | lost: false, requests_left: @request_tries}
  end

  defp check_period(timeout_ms), do: max(div(timeout_ms, 10), 50)

  @mission_messages [M.MissionRequest, M.MissionRequestInt, M.MissionAck, M.MissionCount, M.MissionItemInt, M.MissionItem]

  defp route_to_op(s, %{message: %M.CommandAck{command: command} = ack, compid: compid}),
    do: notify_op(s, command, {:ack, ack, compid})

  defp route_to_op(s, %{message: %m{} = message}) when m in @mission_messages, do: notify_op(s, :mission, {:mission, message})
  # A parameter's value answers a read or set of it, and belongs to a list
  # being fetched when the autopilot sent it (another component's list is
  # another count).
  defp route_to_op(s, %{message: %M.ParamValue{param_id: name} = value, compid: compid}) do
    notify_op(s, {:param, name}, {:param, value})
    if compid in [1, s.state.autopilot_compid], do: notify_op(s, :param_list, {:param, value})
  end

  defp route_to_op(_s, _frame), do: :ok

  # The count of parameters the autopilot's latest value said (the list's size now).
  defp param_count(s, %{message: %M.ParamValue{param_count: n}, compid: compid}) when n != s.param_count do
    if compid in [1, s.state.autopilot_compid], do: %{s | param_count: n}, else: s
  end

  defp param_count(s, _frame), do: s

  defp notify_op(s, key, event) do
    with {:ok, %{pid: pid}} <- Map.fetch(s.ops, key), do: send(pid, event)
  end

  # `from` is nil for the vehicle process's own requests (nobody to answer).
  defp run_op(s, key, module, request, opts, from) do
    request = Map.merge(request, %{sysid: s.sysid, vehicle: s.id, reply_to: from})
    monitor = if from, do: Process.monitor(elem(from, 0))

    if Map.has_key?(s.ops, key) do
      queue = Map.get(s.queued, key, :queue.new())
      %{s | queued: Map.put(s.queued, key, :queue.in({module, request, opts, monitor}, queue))}
    else
      start_op(s, key, module, request, opts, monitor)
    end
  end

  defp start_op(s, key, module, request, opts, monitor) do
    # Through this process, so that each message goes on the path in use when
    # it is sent: a path that changes during a transfer or between a
    # command's retries is followed, and the exchange never knows.
    vehicle = self()
    request = Map.merge(request, %{send: fn message -> GenServer.cast(vehicle, {:send, message}) end, owner: vehicle})

    what =
      case module do
        MissionProtocol -> {:mission, request.operation, request.mission_type}
        ParamProtocol -> {:param, request.name, request.value}
        ParamList -> {:param_list}
        CommandProtocol -> {:command, key}
      end

    opts = Keyword.merge(link_opts(s.state), opts)

    case module.start_link(request, opts) do
      {:ok, pid} ->
        s = if what in [{:mission, :upload, :mission}, {:mission, :clear, :mission}], do: replace_mission(s), else: s
        %{s | ops: Map.put(s.ops, key, %{pid: pid, from: request.reply_to, monitor: monitor, what: what})}

      {:error, reason} ->
        if request.reply_to, do: GenServer.reply(request.reply_to, {:error, crashed(s, what, reason)})
        if monitor, do: Process.demonitor(monitor, [:flush])
        next_op(s, key)
    end
  end

  # From the first MISSION_COUNT or MISSION_CLEAR_ALL on, the vehicle's
  # previous mission is going, whatever the transfer's outcome: its progress
  # is forgotten, and subscribers told, before the new mission can report any.
  defp replace_mission(s), do: publish(s, State.mission_replaced(s.state))

  # What a protocol's timers and patience start from: the autopilot (whose
  # rules say whether mission items may be sent ahead), the measured round
  # trip and the round-trip loss, when known.
  defp link_opts(state) do
    figures = State.link_figures(state)
    [autopilot: state.autopilot, rtt_ms: figures.rtt_ms, loss: figures.loss_rt]
  end

  defp next_op(s, key) do
    with {:ok, queue} <- Map.fetch(s.queued, key),
         {{:value, {module, request, opts, monitor}}, rest} <- :queue.out(queue) do
      start_op(%{s | queued: Map.put(s.queued, key, rest)}, key, module, request, opts, monitor)
    else
      _ -> %{s | queued: Map.delete(s.queued, key)}
    end
  end

  defp crashed(s, {:mission, operation, type}, reason),
    do: %Dolphin.MissionError{operation: operation, vehicle: s.id, mission_type: type, result: :error, detail: "stopped: #{op_words(reason)}"}

  defp crashed(s, {:param, name, value}, reason),
    do: %Dolphin.ParamError{param: name, vehicle: s.id, result: :failed, asked: value, attempts: 0, detail: "stopped: #{op_words(reason)}"}

  defp crashed(s, {:param_list}, reason),
    do: %Dolphin.ParamError{param: "(the list)", vehicle: s.id, result: :failed, attempts: 0, detail: "stopped: #{op_words(reason)}"}

  defp crashed(s, {:command, command}, reason),
    do: %Dolphin.CommandError{command: command, vehicle: s.id, result: :failed, attempts: 0, detail: "stopped: #{op_words(reason)}"}

  # Why a protocol exchange ended without an answer, in words.
  defp op_words(:caller_gone), do: "its caller went away"
  defp op_words(reason), do: "the exchange #{Dolphin.ExitReason.words(reason)}"

  # The data streams (no answer expected), then each message interval as a
  # command of our own through the command protocol, so that its
  # COMMAND_ACKs never settle a caller's command of the same id.
  defp request_telemetry(s) do
    # Every stream at 2 Hz for autopilots that ignore message intervals; the
    # intervals below are what ArduPilot really follows. (Rates are in vehicle
    # time: at a speed-up of 100 this is already 200 frames a second per stream.)
    send_message(s, %M.RequestDataStream{target_system: s.sysid, target_component: 0, req_stream_id: 0, req_message_rate: 2, start_stop: 1})

    # Each interval is asked for until acknowledged, as many times as the
    # link's loss calls for: on a bad radio a request sent once is lost, and
    # a message asked for only by interval (MISSION_CURRENT on some builds,
    # EXTENDED_SYS_STATE) would then never come. While the previous round is
    # still under way, no new one is queued behind it.
    if Map.has_key?(s.ops, 511) do
      s
    else
      Enum.reduce(@intervals, s, fn {msgid, interval_us}, s ->
        params = [msgid * 1.0, interval_us * 1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        request = %{command: 511, params: params, int: false, frame: 0, target_component: 1, progress_to: nil}
        run_op(s, 511, CommandProtocol, request, [], nil)
      end)
    end
  end
end
