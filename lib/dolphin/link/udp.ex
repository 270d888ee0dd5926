defmodule Dolphin.Link.UDP do
  @moduledoc """
  A UDP link: the process that owns one UDP socket (`udpin` or `udpout`).

  It decodes every datagram it receives (a datagram holds whole frames; several
  are fine) and hands each frame to `Dolphin.Vehicles.route/2`, which casts it
  to the vehicle's process: the link never waits on a vehicle. It remembers the
  source address of every system id, so that with `udpin` each vehicle is
  answered where it sends from and many vehicles share one port.

  It also sends the ground station's own HEARTBEAT (type GCS, autopilot
  INVALID) every second of `Dolphin.Clock` time to every known peer, and can
  record every frame in and out to a `.tlog`.

  Options of `start_link/1`: `:endpoint` (a `Dolphin.Link.Endpoint`, required),
  `:name` (the registry key, default the endpoint string), `:gcs_sysid`
  (default 255), `:gcs_compid` (default 190), `:tlog` (a path), `:router` (a
  2-arity function given each frame and the link name; default `Dolphin.Vehicles.route/2`).
  """

  use GenServer

  require Logger

  alias Dolphin.Clock
  alias Dolphin.Link.Endpoint
  alias Dolphin.MAVLink.{Frame, Parser, Tlog}
  alias Dolphin.MAVLink.Ardupilotmega.Heartbeat

  @heartbeat_ms 1_000

  @doc false
  def child_spec(opts) do
    %{id: {__MODULE__, name(opts)}, start: {__MODULE__, :start_link, [opts]}, restart: :permanent}
  end

  @doc "Starts a link; see the module doc for options."
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts, name: via(name(opts)))

  @doc "Sends a message to system `sysid` (0: every known peer) through the link named `name`."
  @spec send_message(term(), byte(), struct()) :: :ok
  def send_message(name, sysid, message), do: GenServer.cast(via(name), {:send, sysid, message})

  @doc "The local port of the link's socket (useful with port 0)."
  @spec port(term()) :: :inet.port_number()
  def port(name), do: GenServer.call(via(name), :port)

  @doc "Decoding counters of the link (`Dolphin.MAVLink.Parser.Stats`) and known peers."
  @spec info(term()) :: map()
  def info(name), do: GenServer.call(via(name), :info)

  defp name(opts), do: Keyword.get_lazy(opts, :name, fn -> Endpoint.to_string(Keyword.fetch!(opts, :endpoint)) end)
  defp via(name), do: {:via, Registry, {Dolphin.Registry, {:link, name}}}

  @impl true
  def init(opts) do
    %Endpoint{} = endpoint = Keyword.fetch!(opts, :endpoint)
    {port, remote} = if endpoint.kind == :udpin, do: {endpoint.port, nil}, else: {0, {endpoint.address, endpoint.port}}
    ip = if endpoint.kind == :udpin, do: [ip: endpoint.address], else: []
    family = if tuple_size(endpoint.address) == 8, do: [:inet6], else: []

    case :gen_udp.open(port, [:binary, active: 100] ++ ip ++ family) do
      {:ok, socket} ->
        # Trapping exits makes a supervisor's shutdown run terminate/2, which
        # flushes the tlog; a crash loses at most its last 200 ms.
        Process.flag(:trap_exit, true)
        tlog = with path when is_binary(path) <- opts[:tlog], do: File.open!(path, [:append, :binary, :raw, {:delayed_write, 65_536, 200}])
        send(self(), :heartbeat)

        {:ok,
         %{
           name: name(opts),
           endpoint: endpoint,
           socket: socket,
           remote: remote,
           peers: %{},
           seq: 0,
           gcs: {Keyword.get(opts, :gcs_sysid, 255), Keyword.get(opts, :gcs_compid, 190)},
           router: Keyword.get(opts, :router, &Dolphin.Vehicles.route/2),
           stats: Parser.stats(Parser.new()),
           tlog: tlog
         }}

      {:error, reason} ->
        {:stop, {:cannot_open, Endpoint.to_string(endpoint), :inet.format_error(reason)}}
    end
  end

  @impl true
  def handle_info({:udp, socket, ip, port, datagram}, %{socket: socket} = state) do
    # A datagram is whole frames: decode it on its own, then end it.
    {frames, parser} = Parser.feed(Parser.new(), datagram)
    {last, parser} = Parser.finish(parser)
    state = %{state | stats: add_stats(state.stats, Parser.stats(parser))}

    state =
      Enum.reduce(frames ++ last, state, fn frame, state ->
        record(state, frame.raw)
        state.router.(frame, state.name)
        %{state | peers: Map.put(state.peers, frame.sysid, {ip, port})}
      end)

    {:noreply, state}
  end

  def handle_info({:udp_passive, socket}, %{socket: socket} = state) do
    :ok = :inet.setopts(socket, active: 100)
    {:noreply, state}
  end

  def handle_info(:heartbeat, state) do
    Clock.send_after(self(), :heartbeat, @heartbeat_ms)
    heartbeat = %Heartbeat{type: 6, autopilot: 8, base_mode: 0, custom_mode: 0, system_status: 4}
    {:noreply, transmit(state, 0, heartbeat)}
  end

  @impl true
  def handle_cast({:send, sysid, message}, state), do: {:noreply, transmit(state, sysid, message)}

  @impl true
  def handle_call(:port, _from, state) do
    {:ok, port} = :inet.port(state.socket)
    {:reply, port, state}
  end

  def handle_call(:info, _from, state), do: {:reply, %{stats: state.stats, peers: state.peers}, state}

  @impl true
  def terminate(_reason, %{tlog: tlog}) when tlog != nil, do: File.close(tlog)
  def terminate(_reason, _state), do: :ok

  defp transmit(state, sysid, message) do
    {gcs_sysid, gcs_compid} = state.gcs
    bytes = Frame.encode(message, sysid: gcs_sysid, compid: gcs_compid, seq: state.seq)

    for address <- destinations(state, sysid) do
      case :gen_udp.send(state.socket, address, bytes) do
        :ok -> :ok
        {:error, reason} -> Logger.warning("link #{state.name}: cannot send to #{inspect(address)}: #{:inet.format_error(reason)}")
      end
    end

    record(state, bytes)
    %{state | seq: rem(state.seq + 1, 256)}
  end

  defp destinations(%{remote: remote}, _sysid) when remote != nil, do: [remote]
  defp destinations(%{peers: peers}, 0), do: peers |> Map.values() |> Enum.uniq()

  defp destinations(%{peers: peers}, sysid) do
    case Map.fetch(peers, sysid) do
      {:ok, address} -> [address]
      :error -> []
    end
  end

  defp record(%{tlog: nil}, _bytes), do: :ok
  defp record(%{tlog: io}, bytes), do: IO.binwrite(io, Tlog.record(System.os_time(:microsecond), bytes))

  defp add_stats(total, more) do
    Map.merge(total, more, fn
      :__struct__, v, _ -> v
      _key, a, b -> a + b
    end)
  end
end
