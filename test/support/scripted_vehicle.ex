defmodule Dolphin.Test.ScriptedVehicle do
  @moduledoc """
  A scripted vehicle for tests and benchmarks. It answers COMMAND_LONG
  (accepting a command whose param1 is even, denying one whose param1 is odd,
  and recording every command it receives), and plays the vehicle side of the
  MAVLink mission protocol by the simulator's rules, which are ArduCopter's
  (`Dolphin.Sim.MissionServer`: items asked for with MISSION_REQUEST,
  INVALID_SEQUENCE and nothing else for an unexpected item, a re-request after
  a second without one, OPERATION_CANCELLED after 8 s without an item,
  MAV_MISSION_ERROR for an item when no upload is under way, NO_SPACE over a
  limit) — but item 0 is kept as sent, not taken for home — over UDP on
  127.0.0.1, behind a link that can drop, duplicate and reorder datagrams in
  both directions.

  It also keeps parameters, as ArduPilot serves them: PARAM_REQUEST_LIST
  answered with every PARAM_VALUE (index, count, MAV_PARAM_TYPE, the value
  cast to a float), PARAM_REQUEST_READ by name or index, PARAM_SET of a
  known name answered with the value kept (clamped to its range), an
  unknown name ignored.

  Options: `:port` (the ground station's), `:sysid`, `:limit` (items), `:loss`,
  `:duplicate`, `:reorder` (probabilities), `:silent` (it hears, and counts
  what it hears, but its answers are lost: only heartbeats come),
  `:timesync` (answers TIMESYNC as ArduPilot does, so that the ground
  station measures the link; default false: its loss is then judged
  total, and every exchange given the most tries), `:seed`, `:speedup` (of its own
  timers, to match `Dolphin.Clock`), `:params` (`%{name => {value, type,
  range}}`, range `{low, high}` or nil; default `params(300)`).
  """

  use GenServer

  alias Dolphin.MAVLink.{Frame, Parser}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.MissionServer

  def start_link(opts), do: GenServer.start_link(__MODULE__, opts)

  @doc "The items the vehicle holds now (mission type 0 mission, 1 fence, 2 rally)."
  def mission(pid, type \\ 0), do: GenServer.call(pid, {:mission, type})

  @doc "The commands received so far, oldest first, as `{command, param1}` (repeats included)."
  def commands(pid), do: GenServer.call(pid, :commands)

  @doc """
  The parameter requests received since the last call, oldest first:
  `:list` (PARAM_REQUEST_LIST), `{:index, i}` or `{:name, name}`
  (PARAM_REQUEST_READ), repeats included.
  """
  def take_param_requests(pid), do: GenServer.call(pid, :take_param_requests)

  @doc "Changes the link's faults."
  def set_faults(pid, faults), do: GenServer.call(pid, {:faults, faults})

  @doc "A parameter more (its list's count grows, as an autopilot's does when a feature is enabled): REAL32, no range."
  def add_param(pid, name, value), do: GenServer.call(pid, {:add_param, name, value})

  @doc """
  Given its process: the parameters it keeps now, `%{name => value}`.
  Given a number `n`: `n` parameters of every MAV_PARAM_TYPE ArduPilot
  uses (INT8, INT16, INT32, REAL32), named as ArduPilot's are (`P0_GAIN`,
  ...), every fourth one with a range (its `:params` option).
  """
  def params(pid) when is_pid(pid), do: GenServer.call(pid, :params)

  def params(n) when is_integer(n) do
    types = [2, 4, 6, 9]

    Map.new(0..(n - 1)//1, fn i ->
      type = Enum.at(types, rem(i, 4))
      value = if type == 9, do: i / 8, else: rem(i * 7, 120) - 20
      {"P#{i}_#{Enum.at(["GAIN", "RATE", "MAX", "TRIM"], rem(i, 4))}", {value, type, if(rem(i, 4) == 3, do: {-10.0, 10.0})}}
    end)
  end

  @impl true
  def init(opts) do
    {:ok, socket} = :gen_udp.open(0, [:binary, active: true, ip: {127, 0, 0, 1}])
    :rand.seed(:exsss, {Keyword.get(opts, :seed, 1), 2, 3})

    s = %{
      socket: socket,
      port: Keyword.fetch!(opts, :port),
      sysid: Keyword.fetch!(opts, :sysid),
      faults: Map.new(Keyword.take(opts, [:loss, :duplicate, :reorder, :silent])),
      speedup: Keyword.get(opts, :speedup, 1),
      timesync: Keyword.get(opts, :timesync, false),
      missions: MissionServer.new(home: false, limit: Keyword.get(opts, :limit, 700)),
      # The mission server's timer: which one is current.
      timer: nil,
      commands: [],
      param_requests: [],
      held: nil,
      seq: 0,
      params: Keyword.get_lazy(opts, :params, fn -> params(300) end)
    }

    send(self(), :heartbeat)
    {:ok, s}
  end

  @impl true
  def handle_call({:mission, type}, _from, s), do: {:reply, Enum.map(MissionServer.items(s.missions, type), &normalise/1), s}
  def handle_call(:commands, _from, s), do: {:reply, Enum.reverse(s.commands), s}
  def handle_call(:take_param_requests, _from, s), do: {:reply, Enum.reverse(s.param_requests), %{s | param_requests: []}}
  def handle_call({:faults, faults}, _from, s), do: {:reply, :ok, %{s | faults: Map.new(faults)}}
  def handle_call({:add_param, name, value}, _from, s), do: {:reply, :ok, %{s | params: Map.put(s.params, name, {value, 9, nil})}}
  def handle_call(:params, _from, s), do: {:reply, Map.new(s.params, fn {name, {value, _, _}} -> {name, value} end), s}

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

  # The mission server's re-request timer, in its (sped-up) time.
  def handle_info({:mission_timer, ref}, %{timer: ref} = s) do
    {missions, replies} = MissionServer.timeout(s.missions, now(s))
    {:noreply, reply(%{s | missions: missions}, replies)}
  end

  def handle_info({:mission_timer, _old}, s), do: {:noreply, s}
  def handle_info(:flush_held, s), do: {:noreply, flush_held(s)}

  defp receive_datagram(s, datagram) do
    {frames, _} = Parser.feed(Parser.new(), datagram)
    Enum.reduce(frames, s, &handle_frame(&1.message, &2))
  end

  defp handle_frame(%M.CommandLong{command: command, param1: p1}, s) do
    result = if rem(trunc(p1), 2) == 0, do: 0, else: 2
    s = %{s | commands: [{command, p1} | s.commands]}
    transmit(s, %M.CommandAck{command: command, result: result, target_system: 255, target_component: 190})
  end

  @mission_messages [M.MissionCount, M.MissionItemInt, M.MissionItem, M.MissionRequestList, M.MissionRequestInt, M.MissionRequest, M.MissionClearAll, M.MissionAck]

  defp handle_frame(%m{} = message, s) when m in @mission_messages do
    {missions, replies} = MissionServer.handle(s.missions, message, {255, 190}, %{now: now(s), home: nil})
    reply(%{s | missions: missions}, replies)
  end

  defp handle_frame(%M.ParamRequestList{}, s) do
    s = %{s | param_requests: [:list | s.param_requests]}

    s.params |> names() |> Enum.with_index() |> Enum.reduce(s, fn {name, i}, s -> transmit(s, param_value(s, name, i)) end)
  end

  defp handle_frame(%M.ParamRequestRead{param_index: i}, s) when i >= 0 do
    s = %{s | param_requests: [{:index, i} | s.param_requests]}

    case Enum.at(names(s.params), i) do
      nil -> s
      name -> transmit(s, param_value(s, name, i))
    end
  end

  defp handle_frame(%M.ParamRequestRead{param_id: name}, s) do
    s = %{s | param_requests: [{:name, name} | s.param_requests]}

    case Enum.find_index(names(s.params), &(&1 == name)) do
      nil -> s
      i -> transmit(s, param_value(s, name, i))
    end
  end

  defp handle_frame(%M.ParamSet{param_id: name, param_value: asked}, s) do
    case s.params do
      %{^name => {_, type, range}} ->
        kept = clamp(if(type == 9, do: asked, else: round(asked)), range)
        s = %{s | params: Map.put(s.params, name, {kept, type, range})}
        transmit(s, param_value(s, name, Enum.find_index(names(s.params), &(&1 == name))))

      _ ->
        s
    end
  end

  defp handle_frame(%M.Timesync{tc1: 0, ts1: ts1}, %{timesync: true} = s), do: transmit(s, %M.Timesync{tc1: System.os_time(:nanosecond), ts1: ts1})

  defp handle_frame(_other, s), do: s

  defp names(params), do: params |> Map.keys() |> Enum.sort()

  defp clamp(v, nil), do: v
  defp clamp(v, {low, high}), do: v |> max(low) |> min(high)

  defp param_value(s, name, i) do
    {value, type, _} = Map.fetch!(s.params, name)
    %M.ParamValue{param_id: name, param_value: value * 1.0, param_type: type, param_count: map_size(s.params), param_index: i}
  end

  # The vehicle's clock: real time sped up as the ground station's is.
  defp now(s), do: System.monotonic_time(:millisecond) * s.speedup

  # What the mission server says goes out; its timer is set again.
  defp reply(s, replies) do
    s =
      Enum.reduce(replies, s, fn
        {:send, message}, s -> transmit(s, message)
        _text_or_change, s -> s
      end)

    case MissionServer.deadline(s.missions) do
      nil ->
        %{s | timer: nil}

      due ->
        ref = make_ref()
        Process.send_after(self(), {:mission_timer, ref}, max(1, ceil((due - now(s)) / s.speedup)))
        %{s | timer: ref}
    end
  end

  # What the vehicle keeps of an item (targets are the sender's business).
  defp normalise(item), do: %{item | target_system: 0, target_component: 0}

  defp transmit(s, message, faults? \\ true) do
    bytes = Frame.encode(message, sysid: s.sysid, compid: 1, seq: s.seq)
    s = %{s | seq: rem(s.seq + 1, 256)}

    cond do
      not faults? -> send_now(s, bytes)
      Map.get(s.faults, :silent, false) -> s
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
