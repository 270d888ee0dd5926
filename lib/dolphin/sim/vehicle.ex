defmodule Dolphin.Sim.Vehicle do
  @moduledoc false
  # One simulated vehicle's process: its own UDP socket, sending to the ground
  # station as ArduPilot SITL's `--serial0 udpclient:HOST:PORT` does, and
  # answering whoever writes to it. It moves bytes (through the link's faults)
  # and time; the vehicle itself is the pure Dolphin.Sim.Copter.
  #
  # Time: the model is stepped in fixed steps of @step_ms of vehicle time,
  # kept in line with Dolphin.Clock: at each tick the model catches up with
  # the clock (at most @max_catch_up steps at once, so an overloaded host
  # makes the vehicle fall behind rather than freeze its mailbox). `lag_ms`
  # says how far behind the clock the vehicle is.

  use GenServer, restart: :transient

  import Bitwise, only: [<<<: 2]

  require Logger

  alias Dolphin.Clock
  alias Dolphin.MAVLink.{Frame, Parser}
  alias Dolphin.Sim.{Copter, Faults}

  @step_ms 50
  @max_catch_up 40

  def child_spec(opts), do: %{id: {__MODULE__, key(opts)}, start: {__MODULE__, :start_link, [opts]}, restart: :transient}

  # `register: false` leaves the process unnamed (benchmarks run several
  # fleets whose system ids repeat, each sending to its own ground station).
  def start_link(opts) do
    if Keyword.get(opts, :register, true),
      do: GenServer.start_link(__MODULE__, opts, name: {:via, Registry, {Dolphin.Instance.names().registry, {:sim, key(opts)}}}),
      else: GenServer.start_link(__MODULE__, opts)
  end

  # How Dolphin.Sim names the vehicle: its system id, or {network, system id}
  # for a vehicle of a named network (which may reuse another's system ids).
  defp key(opts) do
    case Keyword.get(opts, :network) do
      nil -> Keyword.fetch!(opts, :sysid)
      network -> {network, Keyword.fetch!(opts, :sysid)}
    end
  end

  @impl true
  def init(opts) do
    sysid = Keyword.fetch!(opts, :sysid)
    {address, port} = Keyword.fetch!(opts, :gcs)
    bind = if loopback?(address), do: {127, 0, 0, 1}, else: {0, 0, 0, 0}

    case :gen_udp.open(0, [:binary, active: 100, ip: bind, recbuf: 1 <<< 20]) do
      {:ok, socket} ->
        seed = Keyword.get(opts, :seed, 1)
        model = Copter.new(sysid, Keyword.fetch!(opts, :home), Map.new(Keyword.get(opts, :config, %{})))
        model = %{model | uid: Keyword.get(opts, :uid, model.uid)}
        faults = Faults.new(Keyword.get(opts, :faults, %{}), {seed, key(opts)})

        s = %{
          sysid: sysid,
          socket: socket,
          gcs: {address, port},
          model: model,
          faults_out: faults,
          faults_in: Faults.new(Faults.to_map(faults), {seed, key(opts), :in}),
          seqs: %{},
          clock_origin: Clock.now_ms(),
          lag_ms: 0,
          unsendable: MapSet.new(),
          sent: 0,
          received: 0,
          companion: companion(opts, seed),
          # Actions to do when a mission item is reached (Dolphin.Sim.on_item_reached/3).
          on_item_reached: %{}
        }

        # The first heartbeat at once: a booting vehicle is heard at once.
        s = s |> update_model(&Copter.say(&1, Dolphin.Sim.Streams.heartbeat(&1))) |> transmit()
        send(self(), :tick)
        {:ok, s}

      {:error, why} ->
        {:stop, {:cannot_open, "simulated vehicle #{sysid}", :inet.format_error(why)}}
    end
  end

  # Its sensors' companion computer (Dolphin.Sim.Companion), when it carries sensors.
  defp companion(opts, seed) do
    case Keyword.get(opts, :sensors, []) do
      [] -> nil
      sensors -> Dolphin.Sim.Companion.new(sensors, Keyword.get(opts, :world), rate_hz: Keyword.get(opts, :sensor_rate_hz), noise: Keyword.get(opts, :sensor_noise), seed: {seed, key(opts)})
    end
  end

  defp loopback?({127, _, _, _}), do: true
  defp loopback?(_), do: false

  @impl true
  def handle_call(:info, _from, s) do
    m = s.model

    info = %{
      sysid: s.sysid,
      port: elem(:inet.sockname(s.socket), 1) |> elem(1),
      time_ms: m.time_ms,
      lag_ms: s.lag_ms,
      mode: m.mode,
      armed: m.armed,
      landed: m.landed,
      position: Copter.position(m),
      velocity: %{north: m.vn, east: m.ve, up: m.vz},
      home: m.home,
      battery: m.battery,
      mission: Dolphin.Sim.MissionServer.items(m.missions),
      current: m.current,
      mission_state: m.mission_state,
      photos: m.photos,
      speed: m.speed,
      faults: Faults.to_map(s.faults_out),
      # The :disarms_at_arming fault's disarms still to come.
      disarms_at_arming: m.config.disarms_at_arming,
      sensors: if(s.companion, do: s.companion.sensors, else: []),
      sent: s.sent,
      received: s.received
    }

    {:reply, {:ok, info}, s}
  end

  def handle_call({:faults, changes}, _from, s) do
    {:reply, :ok, %{s | faults_out: Faults.update(s.faults_out, changes), faults_in: Faults.update(s.faults_in, changes)}}
  rescue
    e in ArgumentError -> {:reply, Dolphin.Sim.Error.bad_option(Exception.message(e)), s}
  end

  def handle_call({:on_item_reached, seq, action}, _from, s) do
    # Faults are checked now, so that a bad one is said to the caller, not at the item.
    with {:faults, faults} <- action, do: Faults.update(s.faults_out, faults)
    {:reply, :ok, %{s | on_item_reached: Map.update(s.on_item_reached, seq, [action], &(&1 ++ [action]))}}
  rescue
    e in ArgumentError -> {:reply, Dolphin.Sim.Error.bad_option(Exception.message(e)), s}
  end

  def handle_call({:set, :battery, fraction}, _from, s), do: {:reply, :ok, update_model(s, &%{&1 | battery: fraction * 1.0})}

  @impl true
  def handle_info(:tick, s) do
    target = Clock.now_ms() - s.clock_origin
    {model, steps} = catch_up(real_now(s.model), target, 0)
    # The streams once, after the last step: several at once (a pause of the host) send their present, not a burst of the past.
    model = if steps > 0, do: Dolphin.Sim.Streams.due(model), else: model
    lag = max(target - model.time_ms - @step_ms, 0)
    s = s |> Map.put(:model, model) |> Map.put(:lag_ms, lag) |> transmit() |> sense()

    if steps == 0 or lag > 0 do
      # Wait for the clock to move on by the rest of a step.
      Clock.send_after(self(), :tick, max(@step_ms - (target - model.time_ms), 1))
    else
      Clock.send_after(self(), :tick, @step_ms)
    end

    {:noreply, s}
  end

  def handle_info({:udp, socket, _ip, _port, datagram}, %{socket: socket} = s) do
    {deliveries, faults} = Faults.apply(s.faults_in, datagram)
    s = %{s | faults_in: faults}

    s =
      Enum.reduce(deliveries, s, fn
        {0, bytes}, s -> receive_datagram(s, bytes)
        {delay, bytes}, s -> tap(s, fn _ -> Clock.send_after(self(), {:late_in, bytes}, delay) end)
      end)

    {:noreply, transmit(s)}
  end

  def handle_info({:udp_passive, socket}, %{socket: socket} = s) do
    :ok = :inet.setopts(socket, active: 100)
    {:noreply, s}
  end

  # Dolphin.Sim.on_item_reached/3's :crash: silenced already, the process ends
  # as a vehicle destroyed (a normal exit: its supervisor leaves it gone).
  def handle_info(:crash, s), do: {:stop, :normal, s}

  def handle_info({:late_in, bytes}, s), do: {:noreply, s |> receive_datagram(bytes) |> transmit()}

  def handle_info({:late_out, bytes}, s) do
    send_bytes(s, bytes)
    {:noreply, s}
  end

  # The model's time catches up with the clock after a pause of this host,
  # where ArduPilot SITL's stands still: what needs to tell a pause from
  # silence (an upload's patience) reads real time as well.
  defp real_now(model), do: %{model | real_ms: System.monotonic_time(:millisecond)}

  defp catch_up(model, target, steps) when steps < @max_catch_up and model.time_ms + @step_ms <= target,
    do: catch_up(Copter.advance(model, @step_ms), target, steps + 1)

  defp catch_up(model, _target, steps), do: {model, steps}

  defp receive_datagram(s, bytes) do
    {frames, _parser} = Parser.feed(Parser.new(), bytes)
    s = %{s | received: s.received + 1, model: real_now(s.model)}

    Enum.reduce(frames, s, fn frame, s ->
      if for_us?(frame.message, s.sysid),
        do: update_model(s, &Copter.handle(&1, frame.message, {frame.sysid, frame.compid})),
        else: s
    end)
  end

  # Vehicles ignore what is addressed to another system (0 is everyone).
  defp for_us?(%{target_system: target}, sysid), do: target == 0 or target == sysid
  defp for_us?(_message, _sysid), do: true

  defp update_model(s, fun), do: %{s | model: fun.(s.model)}

  defp transmit(s) do
    {outputs, model} = Copter.flush(s.model)
    Enum.reduce(outputs, %{s | model: model}, &transmit_one/2)
  end

  defp sense(%{companion: nil} = s), do: s

  defp sense(s) do
    {outputs, companion} = Dolphin.Sim.Companion.step(s.companion, s.model)
    Enum.reduce(outputs, %{s | companion: companion}, &transmit_one/2)
  end

  # A reboot forgets the actions asked for at mission items: they were for the flight it ends.
  defp transmit_one({:reboot, nil}, s), do: %{s | model: Copter.reboot(s.model), clock_origin: Clock.now_ms(), on_item_reached: %{}}

  defp transmit_one({compid, message}, s) do
    seq = Map.get(s.seqs, compid, 0)

    s =
      case encode(message, s.sysid, compid, seq) do
        {:ok, bytes} -> send_frame(s, compid, seq, bytes)
        {:error, kind, e} -> unsendable(s, kind, e)
      end

    case message do
      %Dolphin.MAVLink.Ardupilotmega.MissionItemReached{seq: item} -> item_reached(s, item)
      _ -> s
    end
  end

  # Right after the item's report has gone: the actions asked for at it.
  defp item_reached(s, item) do
    case Map.pop(s.on_item_reached, item) do
      {nil, _} -> s
      {actions, rest} -> Enum.reduce(actions, %{s | on_item_reached: rest}, &item_action/2)
    end
  end

  defp item_action({:faults, faults}, s), do: %{s | faults_out: Faults.update(s.faults_out, faults), faults_in: Faults.update(s.faults_in, faults)}
  defp item_action({:battery, fraction}, s), do: update_model(s, &%{&1 | battery: fraction * 1.0})

  # Silent at once; the process ends once the frames its faults hold back
  # (latency, reordering: the item's report among them) have gone out.
  defp item_action(:crash, s) do
    case Faults.longest_hold(s.faults_out) do
      0 -> send(self(), :crash)
      held -> Clock.send_after(self(), :crash, held + 1)
    end

    item_action({:faults, silence: true}, s)
  end

  # A value the message cannot carry (a position off the map...) is a fault
  # of the model or of what it was told: said once per kind of message, and
  # the message dropped. Raised here, it would restart the vehicle, which
  # would meet the same value again, for ever.
  defp encode(message, sysid, compid, seq) do
    {:ok, Frame.encode(message, sysid: sysid, compid: compid, seq: seq)}
  rescue
    e in ArgumentError -> {:error, message.__struct__, e}
  end

  defp unsendable(s, kind, e) do
    if MapSet.member?(s.unsendable, kind) do
      s
    else
      Logger.error("simulated vehicle #{s.sysid}: #{Exception.message(e)}; such messages are not sent")
      %{s | unsendable: MapSet.put(s.unsendable, kind)}
    end
  end

  defp send_frame(s, compid, seq, bytes) do
    {deliveries, faults} = Faults.apply(s.faults_out, bytes)

    Enum.each(deliveries, fn
      {0, bytes} -> send_bytes(s, bytes)
      {delay, bytes} -> Clock.send_after(self(), {:late_out, bytes}, delay)
    end)

    %{s | seqs: Map.put(s.seqs, compid, rem(seq + 1, 256)), faults_out: faults, sent: s.sent + 1}
  end

  defp send_bytes(%{socket: socket, gcs: {address, port}}, bytes) do
    # A full socket buffer or an unreachable ground station loses the datagram, as a radio would.
    _ = :gen_udp.send(socket, address, port, bytes)
    :ok
  end
end
