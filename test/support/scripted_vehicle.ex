defmodule Dolphin.Test.ScriptedVehicle do
  @moduledoc """
  A scripted vehicle for tests and benchmarks. It answers COMMAND_LONG
  (accepting a command whose param1 is even, denying one whose param1 is odd,
  and recording every command it receives), and plays the vehicle side of the
  MAVLink mission protocol as ArduCopter does (items asked for with MISSION_REQUEST,
  INVALID_SEQUENCE for an unexpected item while it goes on asking, a re-request
  every second of silence and OPERATION_CANCELLED after 8, NO_SPACE over a
  limit), over UDP on 127.0.0.1, behind a link that can drop, duplicate and
  reorder datagrams in both directions.

  Options: `:port` (the ground station's), `:sysid`, `:limit` (items), `:loss`,
  `:duplicate`, `:reorder` (probabilities), `:seed`, `:speedup` (of its own
  timers, to match `Dolphin.Clock`).
  """

  use GenServer

  alias Dolphin.MAVLink.{Frame, Parser}
  alias Dolphin.MAVLink.Ardupilotmega, as: M

  def start_link(opts), do: GenServer.start_link(__MODULE__, opts)

  @doc "The items the vehicle holds now (mission type 0 mission, 1 fence, 2 rally)."
  def mission(pid, type \\ 0), do: GenServer.call(pid, {:mission, type})

  @doc "The commands received so far, oldest first, as `{command, param1}` (repeats included)."
  def commands(pid), do: GenServer.call(pid, :commands)

  @doc "Changes the link's faults."
  def set_faults(pid, faults), do: GenServer.call(pid, {:faults, faults})

  @impl true
  def init(opts) do
    {:ok, socket} = :gen_udp.open(0, [:binary, active: true, ip: {127, 0, 0, 1}])
    :rand.seed(:exsss, {Keyword.get(opts, :seed, 1), 2, 3})

    s = %{
      socket: socket,
      port: Keyword.fetch!(opts, :port),
      sysid: Keyword.fetch!(opts, :sysid),
      limit: Keyword.get(opts, :limit, 700),
      faults: Map.new(Keyword.take(opts, [:loss, :duplicate, :reorder])),
      speedup: Keyword.get(opts, :speedup, 1),
      # mission type => items
      lists: %{},
      commands: [],
      upload: nil,
      held: nil,
      seq: 0
    }

    send(self(), :heartbeat)
    {:ok, s}
  end

  @impl true
  def handle_call({:mission, type}, _from, s), do: {:reply, Map.get(s.lists, type, []), s}
  def handle_call(:commands, _from, s), do: {:reply, Enum.reverse(s.commands), s}
  def handle_call({:faults, faults}, _from, s), do: {:reply, :ok, %{s | faults: Map.new(faults)}}

  @impl true
  def handle_info(:heartbeat, s) do
    Process.send_after(self(), :heartbeat, 200)
    # Heartbeats are not subject to the faults: they keep the vehicle known.
    {:noreply, transmit(s, %M.Heartbeat{type: 2, autopilot: 3, custom_mode: 4, system_status: 4}, false)}
  end

  # What the ground station sends suffers the same faults on its way in.
  def handle_info({:udp, _socket, _ip, _port, datagram}, s) do
    cond do
      :rand.uniform() < Map.get(s.faults, :loss, 0) ->
        {:noreply, s}

      :rand.uniform() < Map.get(s.faults, :reorder, 0) ->
        Process.send_after(self(), {:late, datagram}, 5)
        {:noreply, s}

      :rand.uniform() < Map.get(s.faults, :duplicate, 0) ->
        {:noreply, s |> receive_datagram(datagram) |> receive_datagram(datagram)}

      true ->
        {:noreply, receive_datagram(s, datagram)}
    end
  end

  def handle_info({:late, datagram}, s), do: {:noreply, receive_datagram(s, datagram)}

  # ArduPilot re-asks every second of its time, 8 times, then gives up.
  def handle_info({:rerequest, ref}, %{upload: %{ref: ref} = up} = s) do
    if up.tries >= 8 do
      s = transmit(%{s | upload: nil}, ack(up.type, 15))
      {:noreply, s}
    else
      s = %{s | upload: %{up | tries: up.tries + 1}}
      {:noreply, request_next(s)}
    end
  end

  def handle_info({:rerequest, _old}, s), do: {:noreply, s}
  def handle_info(:flush_held, s), do: {:noreply, flush_held(s)}

  defp receive_datagram(s, datagram) do
    {frames, _} = Parser.feed(Parser.new(), datagram)
    Enum.reduce(frames, s, &handle_frame(&1.message, &2))
  end

  defp handle_frame(%M.MissionCount{count: count, mission_type: type}, s) do
    cond do
      count > s.limit -> transmit(s, ack(type, 4))
      count == 0 -> transmit(%{s | lists: Map.put(s.lists, type, []), upload: nil}, ack(type, 0))
      true -> request_next(%{s | upload: %{type: type, count: count, items: [], tries: 0, ref: nil}})
    end
  end

  defp handle_frame(%M.MissionItemInt{seq: seq, mission_type: type} = item, %{upload: %{type: type} = up} = s) do
    expected = length(up.items)

    cond do
      seq != expected ->
        transmit(s, ack(type, 13)) |> request_next()

      expected + 1 == up.count ->
        list = Enum.reverse([normalise(item) | up.items])
        transmit(%{s | lists: Map.put(s.lists, type, list), upload: nil}, ack(type, 0))

      true ->
        request_next(%{s | upload: %{up | items: [normalise(item) | up.items], tries: 0}})
    end
  end

  defp handle_frame(%M.CommandLong{command: command, param1: p1}, s) do
    result = if rem(trunc(p1), 2) == 0, do: 0, else: 2
    s = %{s | commands: [{command, p1} | s.commands]}
    transmit(s, %M.CommandAck{command: command, result: result, target_system: 255, target_component: 190})
  end

  defp handle_frame(%M.MissionRequestList{mission_type: type}, s),
    do: transmit(s, %M.MissionCount{target_system: 255, target_component: 190, count: length(Map.get(s.lists, type, [])), mission_type: type})

  defp handle_frame(%M.MissionRequestInt{seq: seq, mission_type: type}, s) do
    case Enum.at(Map.get(s.lists, type, []), seq) do
      nil -> s
      item -> transmit(s, %{item | target_system: 255, target_component: 190})
    end
  end

  defp handle_frame(%M.MissionClearAll{mission_type: type}, s),
    do: transmit(%{s | lists: Map.put(s.lists, type, []), upload: nil}, ack(type, 0))

  defp handle_frame(_other, s), do: s

  defp request_next(%{upload: up} = s) do
    ref = make_ref()
    Process.send_after(self(), {:rerequest, ref}, max(1, div(1_000, s.speedup)))
    s = %{s | upload: %{up | ref: ref}}
    transmit(s, %M.MissionRequest{target_system: 255, target_component: 190, seq: length(up.items), mission_type: up.type})
  end

  defp ack(mission_type, result), do: %M.MissionAck{target_system: 255, target_component: 190, type: result, mission_type: mission_type}

  # What the vehicle keeps of an item (targets are the sender's business).
  defp normalise(item), do: %{item | target_system: 0, target_component: 0}

  defp transmit(s, message, faults? \\ true) do
    bytes = Frame.encode(message, sysid: s.sysid, compid: 1, seq: s.seq)
    s = %{s | seq: rem(s.seq + 1, 256)}

    cond do
      not faults? -> send_now(s, bytes)
      :rand.uniform() < Map.get(s.faults, :loss, 0) -> s
      :rand.uniform() < Map.get(s.faults, :reorder, 0) and s.held == nil -> hold(s, bytes)
      true -> s |> send_now(bytes) |> maybe_duplicate(bytes) |> flush_held()
    end
  end

  defp hold(s, bytes) do
    Process.send_after(self(), :flush_held, 5)
    %{s | held: bytes}
  end

  defp flush_held(%{held: nil} = s), do: s
  defp flush_held(%{held: bytes} = s), do: send_now(%{s | held: nil}, bytes)

  defp maybe_duplicate(s, bytes),
    do: if(:rand.uniform() < Map.get(s.faults, :duplicate, 0), do: send_now(s, bytes), else: s)

  defp send_now(s, bytes) do
    :ok = :gen_udp.send(s.socket, {127, 0, 0, 1}, s.port, bytes)
    s
  end
end
