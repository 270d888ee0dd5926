defmodule Dolphin.Vehicles.Vehicle do
  @moduledoc false
  # One process per discovered vehicle: folds its frames into a
  # Dolphin.Vehicles.State, publishes what changed, watches for silence (lost /
  # reconnected) and asks the vehicle for the telemetry the ground station needs.
  # It holds nothing that the next telemetry does not restore, so a crash only
  # costs the state until the next frames.
  use GenServer, restart: :permanent

  alias Dolphin.{Clock, PubSub}
  alias Dolphin.Link.Connection
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Vehicles.{CommandProtocol, MissionProtocol, State}

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

  def child_spec({sysid, _link, _opts} = args),
    do: %{id: {__MODULE__, sysid}, start: {__MODULE__, :start_link, [args]}, restart: :permanent}

  def start_link({sysid, _link, _opts} = args),
    do: GenServer.start_link(__MODULE__, args, name: {:via, Registry, {Dolphin.Registry, {:vehicle, sysid}}})

  @impl true
  def init({sysid, link, opts}) do
    # Command protocols are linked to this process: their exits come as messages.
    Process.flag(:trap_exit, true)
    timeout = Keyword.get(opts, :timeout_ms, Application.get_env(:dolphin, :vehicle_timeout_ms, 20_000))
    send(self(), :request_telemetry)
    Clock.send_after(self(), :check_link, check_period(timeout))

    {:ok,
     %{
       sysid: sysid,
       link: link,
       state: State.new(sysid),
       timeout_ms: timeout,
       lost: false,
       requests_left: @request_tries,
       # Operations under way: a command id, or :mission (one transfer at a
       # time), => {protocol pid, caller}; and what waits for each: a queue of
       # {module, request, opts}.
       ops: %{},
       queued: %{}
     }}
  end

  @impl true
  def handle_cast({:frame, frame, link}, s) do
    s = if s.lost, do: reconnected(s), else: s
    new = State.apply(s.state, frame, Clock.now_ms())

    case State.changes(s.state, new) do
      [] -> :ok
      changes -> PubSub.publish({:vehicle, s.sysid}, {:state, s.sysid, changes})
    end

    route_to_op(s, frame.message)

    # Position telemetry flowing means the requests were heard.
    requests_left = if match?(%M.GlobalPositionInt{}, frame.message), do: 0, else: s.requests_left
    {:noreply, %{s | state: new, link: link, requests_left: requests_left}}
  end

  def handle_cast({:send, message}, s) do
    Connection.send_message(s.link, s.sysid, message)
    {:noreply, s}
  end

  @impl true
  def handle_call(:state, _from, s), do: {:reply, %{s.state | seqs: %{}} |> Map.put(:lost, s.lost), s}

  def handle_call({:set_timeout, ms}, _from, s), do: {:reply, :ok, %{s | timeout_ms: ms}}

  # One command of an id at a time (a COMMAND_ACK names only the command id),
  # one mission transfer at a time; the rest wait their turn. The protocol
  # replies to the caller.
  def handle_call({:command, request, opts}, from, s), do: {:noreply, run_op(s, request.command, CommandProtocol, request, opts, from)}
  def handle_call({:mission, request, opts}, from, s), do: {:noreply, run_op(s, :mission, MissionProtocol, request, opts, from)}

  @impl true
  def handle_info(:request_telemetry, %{requests_left: 0} = s), do: {:noreply, s}

  def handle_info(:request_telemetry, s) do
    request_telemetry(s)
    Clock.send_after(self(), :request_telemetry, @request_every_ms)
    {:noreply, %{s | requests_left: s.requests_left - 1}}
  end

  def handle_info({:EXIT, pid, reason}, s) do
    case Enum.find(s.ops, fn {_key, {p, _from}} -> p == pid end) do
      {key, {_pid, from}} ->
        # A protocol that crashed did not answer its caller.
        if reason != :normal, do: GenServer.reply(from, {:error, crashed(s, key, reason)})
        {:noreply, next_op(%{s | ops: Map.delete(s.ops, key)}, key)}

      nil ->
        {:noreply, s}
    end
  end

  def handle_info(:check_link, s) do
    Clock.send_after(self(), :check_link, check_period(s.timeout_ms))
    last = s.state.link.last_seen_ms

    if not s.lost and last != nil and Clock.now_ms() - last > s.timeout_ms do
      PubSub.publish(:vehicles, {:vehicle_lost, s.sysid})
      PubSub.publish({:vehicle, s.sysid}, {:vehicle_lost, s.sysid})
      {:noreply, %{s | lost: true}}
    else
      {:noreply, s}
    end
  end

  # Heard again after a silence: say so, and ask for telemetry again (the
  # vehicle may have rebooted and forgotten the rates).
  defp reconnected(s) do
    PubSub.publish(:vehicles, {:vehicle_reconnected, s.sysid})
    PubSub.publish({:vehicle, s.sysid}, {:vehicle_reconnected, s.sysid})
    if s.requests_left == 0, do: send(self(), :request_telemetry)
    %{s | lost: false, requests_left: @request_tries}
  end

  defp check_period(timeout_ms), do: max(div(timeout_ms, 10), 50)

  @mission_messages [M.MissionRequest, M.MissionRequestInt, M.MissionAck, M.MissionCount, M.MissionItemInt, M.MissionItem]

  defp route_to_op(s, %M.CommandAck{command: command} = ack), do: notify_op(s, command, {:ack, ack})
  defp route_to_op(s, %m{} = message) when m in @mission_messages, do: notify_op(s, :mission, {:mission, message})
  defp route_to_op(_s, _message), do: :ok

  defp notify_op(s, key, event) do
    with {:ok, {pid, _from}} <- Map.fetch(s.ops, key), do: send(pid, event)
  end

  defp run_op(s, key, module, request, opts, from) do
    request = Map.merge(request, %{sysid: s.sysid, reply_to: from})

    if Map.has_key?(s.ops, key) do
      queue = Map.get(s.queued, key, :queue.new())
      %{s | queued: Map.put(s.queued, key, :queue.in({module, request, opts}, queue))}
    else
      start_op(s, key, module, request, opts)
    end
  end

  defp start_op(s, key, module, request, opts) do
    link = s.link
    sysid = s.sysid
    request = Map.put(request, :send, fn message -> Connection.send_message(link, sysid, message) end)
    {:ok, pid} = module.start_link(request, opts)
    %{s | ops: Map.put(s.ops, key, {pid, request.reply_to})}
  end

  defp next_op(s, key) do
    with {:ok, queue} <- Map.fetch(s.queued, key),
         {{:value, {module, request, opts}}, rest} <- :queue.out(queue) do
      start_op(%{s | queued: Map.put(s.queued, key, rest)}, key, module, request, opts)
    else
      _ -> %{s | queued: Map.delete(s.queued, key)}
    end
  end

  defp crashed(s, :mission, reason),
    do: %Dolphin.MissionError{operation: :upload, vehicle: s.sysid, mission_type: :mission, result: :error, detail: "protocol crashed: #{inspect(reason)}"}

  defp crashed(s, command, reason),
    do: %Dolphin.CommandError{command: command, vehicle: s.sysid, result: :failed, attempts: 0, detail: "protocol crashed: #{inspect(reason)}"}

  defp request_telemetry(s) do
    # MAV_DATA_STREAM_ALL at 4 Hz, then the messages that matter at their own rates.
    Connection.send_message(s.link, s.sysid, %M.RequestDataStream{target_system: s.sysid, target_component: 0, req_stream_id: 0, req_message_rate: 4, start_stop: 1})

    for {msgid, interval_us} <- @intervals do
      Connection.send_message(s.link, s.sysid, %M.CommandLong{target_system: s.sysid, target_component: 0, command: 511, param1: msgid * 1.0, param2: interval_us * 1.0})
    end
  end
end
