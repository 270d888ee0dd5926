defmodule Dolphin.Sim.Sidecar do
  @moduledoc """
  Companion computers for vehicles the simulator does not fly — ArduPilot
  SITL's — so that their sensors sense a `Dolphin.Sim.World` too (`mix
  dolphin.sensors`, and `mix dolphin.run --sitl copter:2+smoke --world
  FILE`, which starts one).

  It is plugged in where a real companion computer is: on the autopilot's
  second telemetry port (SITL's `--serial1 udpclient:HOST:PORT`, sending to
  this sidecar's socket). For each autopilot it hears there it asks for
  GLOBAL_POSITION_INT (SET_MESSAGE_INTERVAL), and from each position
  computes its sensors' readings as the simulator's companion does
  (`Dolphin.Sim.Companion`: the same models, rate and noise, in the
  vehicle's time, `time_boot_ms`), sending them back as NAMED_VALUE_FLOAT
  with the vehicle's system id and component 191, with a HEARTBEAT of that
  component. ArduPilot forwards them to its ground station on `--serial0`
  (it routes messages without a target to every other link it has heard
  from), so the ground station hears them as it hears a real companion's.

      {:ok, pid} = Dolphin.Sim.Sidecar.start_link(listen: 0, sensors: [:smoke], world: world)
      port = Dolphin.Sim.Sidecar.port(pid)
      # arducopter ... --serial1 udpclient:127.0.0.1:PORT
  """

  use GenServer

  alias Dolphin.MAVLink.{Frame, Parser}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.Companion

  # Position asked for every 100 ms of vehicle time, asked again every
  # second of real time until it comes.
  @position_interval_us 100_000
  @ask_every_ms 1_000

  @doc """
  Starts a sidecar. Options: `:listen` (a UDP port on 127.0.0.1 to listen
  on, 0 for any, or `{address, port}`: the autopilots send to it first), or `:connect` (`{ip,
  port}`: an autopilot's UDP port to send to first); `:sensors` (models for
  every vehicle, or a map of them by system id; `Dolphin.Sim.Companion.models/0`),
  `:world` (a `Dolphin.Sim.World`), `:rate_hz`, `:noise`, `:seed`.
  """
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts)

  @doc "The UDP port it listens on."
  @spec port(GenServer.server()) :: :inet.port_number()
  def port(sidecar), do: GenServer.call(sidecar, :port)

  @doc "The vehicles it plays a companion computer for, with the readings sent to each: `%{sysid => count}`."
  @spec vehicles(GenServer.server()) :: %{byte() => non_neg_integer()}
  def vehicles(sidecar), do: GenServer.call(sidecar, :vehicles)

  @doc "Stops it."
  @spec stop(GenServer.server()) :: :ok
  def stop(sidecar), do: GenServer.stop(sidecar)

  @impl true
  def init(opts) do
    {ip, port} =
      case Keyword.get(opts, :listen, 0) do
        {ip, port} -> {ip, port}
        port -> {{127, 0, 0, 1}, port}
      end

    case :gen_udp.open(port, [:binary, active: 100, ip: ip]) do
      {:ok, socket} ->
        s = %{
          socket: socket,
          parser: %{},
          sensors: Keyword.get(opts, :sensors, [:smoke]),
          world: Keyword.get(opts, :world) || %Dolphin.Sim.World{},
          companion_opts: [rate_hz: Keyword.get(opts, :rate_hz), noise: Keyword.get(opts, :noise)],
          seed: Keyword.get(opts, :seed, 1),
          peers: %{}
        }

        # Sending first (udpout): a heartbeat a second until the autopilot answers.
        s = Map.put(s, :hello, Keyword.get(opts, :connect))
        if s.hello, do: send(self(), :hello)
        {:ok, s}

      {:error, why} ->
        {:stop, {:cannot_open, "sensor sidecar on UDP port #{port}", :inet.format_error(why)}}
    end
  end

  @impl true
  def handle_call(:port, _from, s), do: {:reply, elem(:inet.port(s.socket), 1), s}
  def handle_call(:vehicles, _from, s), do: {:reply, Map.new(s.peers, fn {id, p} -> {id, p.sent} end), s}

  @impl true
  def handle_info({:udp, socket, ip, port, data}, %{socket: socket} = s) do
    from = {ip, port}
    # Heard from where it sent first: no more hellos.
    s = if s.hello == from, do: %{s | hello: nil}, else: s
    {frames, parser} = Parser.feed(Map.get(s.parser, from, Parser.new()), data)
    s = %{s | parser: Map.put(s.parser, from, parser)}
    {:noreply, Enum.reduce(frames, s, &frame(&2, from, &1))}
  end

  def handle_info({:udp_passive, socket}, %{socket: socket} = s) do
    :ok = :inet.setopts(socket, active: 100)
    {:noreply, s}
  end

  def handle_info(:hello, %{hello: nil} = s), do: {:noreply, s}

  def handle_info(:hello, %{hello: to} = s) do
    send_frame(s, to, 0, 0, %M.Heartbeat{type: 18, autopilot: 8, base_mode: 0, custom_mode: 0, system_status: 4, mavlink_version: 3})
    Process.send_after(self(), :hello, 1_000)
    {:noreply, s}
  end

  def handle_info(_other, s), do: {:noreply, s}

  # The autopilot's frames only (component 1); what it forwards from others is not its place.
  defp frame(s, from, %Frame{sysid: sysid, compid: 1, message: message}) do
    case sensors_of(s, sysid) do
      [] -> s
      sensors -> s |> peer(sysid, from, sensors) |> heard(sysid, message)
    end
  end

  defp frame(s, _from, _frame), do: s

  defp sensors_of(%{sensors: %{} = by_id}, sysid), do: Map.get(by_id, sysid, [])
  defp sensors_of(%{sensors: list}, _sysid), do: list

  defp peer(s, sysid, from, sensors) do
    case s.peers do
      %{^sysid => p} ->
        put_in(s.peers[sysid], %{p | addr: from})

      _ ->
        companion = Companion.new(sensors, s.world, Keyword.put(s.companion_opts, :seed, {s.seed, sysid}))
        put_in(s.peers[sysid], %{addr: from, companion: companion, asked_ms: nil, positioned: false, sent: 0, seq: 0})
    end
  end

  defp heard(s, sysid, %M.GlobalPositionInt{lat: lat, lon: lon} = p) when lat != 0 or lon != 0 do
    peer = s.peers[sysid]
    place = %{lat: lat / 1.0e7, lon: lon / 1.0e7, alt: p.alt / 1000, ground: (p.alt - p.relative_alt) / 1000}
    {outputs, companion} = Companion.step_at(peer.companion, p.time_boot_ms, place)
    peer = %{peer | companion: companion, positioned: true}
    peer = Enum.reduce(outputs, peer, fn {_compid, message}, peer -> say(s, sysid, peer, message) end)
    put_in(s.peers[sysid], peer)
  end

  # Until positions come, they are asked for (again every second).
  defp heard(s, sysid, _message) do
    peer = s.peers[sysid]
    now = System.monotonic_time(:millisecond)

    if peer.positioned or (peer.asked_ms != nil and now - peer.asked_ms < @ask_every_ms) do
      s
    else
      ask = %M.CommandLong{target_system: sysid, target_component: 1, command: 511, param1: 33.0, param2: @position_interval_us * 1.0}
      peer = say(s, sysid, %{peer | asked_ms: now}, ask)
      put_in(s.peers[sysid], peer)
    end
  end

  defp say(s, sysid, peer, message) do
    send_frame(s, peer.addr, sysid, peer.seq, message)
    counted = if match?(%M.NamedValueFloat{}, message), do: 1, else: 0
    %{peer | seq: rem(peer.seq + 1, 256), sent: peer.sent + counted}
  end

  defp send_frame(s, {ip, port}, sysid, seq, message) do
    _ = :gen_udp.send(s.socket, ip, port, Frame.encode(message, sysid: sysid, compid: Companion.compid(), seq: seq))
    :ok
  end
end
