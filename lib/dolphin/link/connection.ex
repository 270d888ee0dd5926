defmodule Dolphin.Link.Connection do
  @moduledoc """
  A link: the process that owns one socket — `udpin`, `udpout` or `tcp` (see
  `Dolphin.Link.Endpoint`).

  It decodes what it receives (a UDP datagram holds whole frames, several are
  fine; a TCP stream splits frames anywhere) and hands the frames to
  `Dolphin.Vehicles.route_all/1`, which casts each vehicle's to its process
  in one message: the link never waits on a vehicle. Datagrams waiting in
  its mailbox (it was busy) are taken in the same wake-up, up to 64, so
  that under load a vehicle's process wakes once for several frames. With `udpin` it remembers the source address of
  every system id, so that each vehicle is answered where it sends from and
  many vehicles share one port. A `tcp` link connects, and reconnects with
  backoff (0.5 s doubling to 5 s) whenever the connection is lost.

  It also sends the ground station's own HEARTBEAT (type GCS, autopilot
  INVALID) every second of `Dolphin.Clock` time to every known peer; can record
  every frame in and out to a `.tlog`; can forward all traffic, both ways, to
  other endpoints (so QGroundControl can watch the fleet); and can sign what it
  sends and check what it receives (MAVLink 2 signing).

  Options of `start_link/1`:

    * `:endpoint` — a `Dolphin.Link.Endpoint` (required);
    * `:name` — the registry key (default: the endpoint string);
    * `:gcs_sysid`, `:gcs_compid` — our identity (default `config :dolphin,
      gcs_sysid:` or 255, and 190);
    * `:tlog` — a path to append every frame to (links given the same path
      record a frame from a vehicle heard on several of them once: see
      "Links that share a .tlog");
    * `:forward` — endpoints (`udpout` ones) that get a copy of all traffic;
    * `:signing` — `[key: KEY, link_id: N, require: boolean]`: outgoing frames
      are signed; incoming signed frames are verified; with `require: true`
      unsigned ones are dropped;
    * `:router` — a 2-arity function given each frame and the path it came
      by, a `t:via/0` (by default the frames go to `Dolphin.Vehicles.route_all/1`
      together, as above);
    * `:network` — the name of the network this link is (see
      `Dolphin.Vehicles.Id`): the vehicles it hears are told apart by system
      id alone, whatever address each sends from, and a vehicle whose system
      id another vehicle has is named `SYSID@NAME`. Without it each remote
      address of a `udpin` link is a network of its own, and any other link is
      one, named by the link's name. (`Dolphin.Sim.Local` names the
      simulator's networks beyond the first so: `sim2`, `sim3`, ...)

  ## Links that share a .tlog

  A vehicle heard on two links (two radios) sends each frame on both. Links
  that record to the same `.tlog` file record such a frame once: a frame
  with the same system, component, sequence number and bytes that another
  link recorded in that file less than a second ago is not recorded again.
  A frame heard twice on the same link is recorded twice (a vehicle that
  reboots restarts its sequence: nothing it sends is taken for a copy), and
  what the ground station sends is recorded by each link that sends it. A
  link's decoding counters (`info/1`) count every frame it received, copies
  included: they are that link's.
  """

  use GenServer

  require Logger

  alias Dolphin.Clock
  alias Dolphin.Link.Endpoint
  alias Dolphin.MAVLink.{Frame, Parser, Signing, Tlog}
  alias Dolphin.MAVLink.Parser.Stats
  alias Dolphin.MAVLink.Ardupilotmega.Heartbeat

  @heartbeat_ms 1_000
  @backoff_min 500
  @backoff_max 5_000
  # How long (real ms) a frame another link recorded in the same .tlog makes
  # an identical one a copy (see "Links that share a .tlog").
  @copy_window_ms 1_000
  # How many datagrams waiting in the mailbox one wake-up takes at most (see handle_info/2).
  @drain_max 64

  @doc false
  def child_spec(opts) do
    %{id: {__MODULE__, name(opts)}, start: {__MODULE__, :start_link, [opts]}, restart: :permanent}
  end

  @doc "Starts a link; see the module doc for options."
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts, name: registered(name(opts), opts[:network]), spawn_opt: spawn_opt())

  @doc """
  The process options of a link: a young heap of 32 Ki words (256 KiB).

  A link decodes a burst (a TCP read, a run of queued datagrams) into frames
  that all stay live until they are routed. With the default 233-word heap a
  4 KiB read's frames are copied by several collections while the parser still
  works on it, a quarter of the decoding time in `bench/codec.exs`, which runs
  its rounds in processes with these options.
  """
  @spec spawn_opt() :: [{:min_heap_size, pos_integer()}]
  def spawn_opt, do: [min_heap_size: 32_768]

  @typedoc """
  The path a frame came by: the link's name, and for a `udpin` link the
  address it came from (nil for `udpout` and `tcp`, whose peer is the one
  they connect to). A vehicle heard on two links, or on one `udpin` link from
  two addresses (a radio and a relay), has two paths.
  """
  @type via :: {term(), {:inet.ip_address(), :inet.port_number()} | nil}

  @doc "Sends a message to system `sysid` (0: every known peer) through the link named `name`."
  @spec send_message(term(), byte(), struct()) :: :ok
  def send_message(name, sysid, message), do: GenServer.cast(via(name), {:send, sysid, message})

  @doc "Sends a message to system `sysid` by a path (`t:via/0`): on its link, to its address."
  @spec send_via(via(), byte(), struct()) :: :ok
  def send_via({name, nil}, sysid, message), do: send_message(name, sysid, message)
  def send_via({name, {_ip, _port} = address}, _sysid, message), do: GenServer.cast(via(name), {:send, {:address, address}, message})
  # A link's name alone (a frame routed by hand): as send_message/3.
  def send_via(name, sysid, message), do: send_message(name, sysid, message)

  @doc "The local port of the link's socket (useful with port 0)."
  @spec port(term()) :: :inet.port_number()
  def port(name), do: GenServer.call(via(name), :port)

  @doc "Decoding counters of the link (`Dolphin.MAVLink.Parser.Stats`), known peers, whether connected."
  @spec info(term()) :: map()
  def info(name), do: GenServer.call(via(name), :info)

  defp name(opts), do: Keyword.get_lazy(opts, :name, fn -> Endpoint.to_string(Keyword.fetch!(opts, :endpoint)) end)
  defp via(name), do: {:via, Registry, {Dolphin.Instance.names().registry, {:link, name}}}

  @doc """
  The network a link was given (its `:network` option), or nil: the
  network a path of it (`t:via/0`) belongs to, named in `Dolphin.Vehicles.Id`.
  """
  @spec network(term()) :: String.t() | nil
  def network(name) do
    case Registry.lookup(Dolphin.Instance.names().registry, {:link, name}) do
      [{_pid, network}] when is_binary(network) -> network
      _ -> nil
    end
  end

  # The link's network is kept beside its name, for network/1 to read without calling it.
  defp registered(name, network) when is_binary(network), do: {:via, Registry, {Dolphin.Instance.names().registry, {:link, name}, network}}
  defp registered(name, nil), do: via(name)

  @impl true
  def init(opts) do
    %Endpoint{} = endpoint = Keyword.fetch!(opts, :endpoint)
    # Trapping exits makes a supervisor's shutdown run terminate/2, which
    # closes the sockets and flushes the tlog; a crash loses at most its last 200 ms.
    Process.flag(:trap_exit, true)
    # The ground station's ear comes first: on a host too busy for all its
    # work the bytes are taken off the socket before anything else runs, so
    # that the kernel's buffer does not overflow and drop them, and the
    # vehicles' processes (which hold what is heard) wait instead.
    Process.flag(:priority, :high)

    # The log first: a log that cannot be written leaves no socket behind.
    with {:ok, tlog} <- open_tlog(opts[:tlog]),
         {:ok, socket} <- open(endpoint),
         {:ok, forward} <- open_forward(Keyword.get(opts, :forward, [])) do
      if endpoint.kind == :tcp, do: send(self(), :connect)
      send(self(), :heartbeat)

      {:ok,
       %{
         name: name(opts),
         endpoint: endpoint,
         socket: socket,
         backoff: @backoff_min,
         peers: %{},
         # Every address heard from: vehicles that share a system id each have one.
         heard_from: MapSet.new(),
         seq: 0,
         gcs: {Keyword.get_lazy(opts, :gcs_sysid, fn -> Application.get_env(:dolphin, :gcs_sysid, 255) end), Keyword.get(opts, :gcs_compid, 190)},
         router: Keyword.get(opts, :router, &Dolphin.Vehicles.route/2),
         # The default router takes what a wake-up decoded at once (Dolphin.Vehicles.route_all/1).
         batch?: not Keyword.has_key?(opts, :router),
         stats: %Stats{},
         # Fresh, for each datagram (see handle_info/2); signed links verify every frame: no fast path.
         datagram_parser: Parser.new(batch: opts[:signing] == nil),
         stream: nil,
         signing: signing(opts[:signing]),
         forward: forward,
         tlog: tlog
       }}
    else
      {:error, reason} -> {:stop, {:cannot_open, Endpoint.to_string(endpoint), reason}}
    end
  end

  defp open_tlog(nil), do: {:ok, nil}

  defp open_tlog(path) do
    case File.open(path, [:append, :binary, :raw, {:delayed_write, 65_536, 200}]) do
      {:ok, io} -> {:ok, {io, Path.expand(path)}}
      {:error, why} -> {:error, "telemetry log #{path}: #{:file.format_error(why)}"}
    end
  end

  defp open(%Endpoint{kind: :tcp}), do: {:ok, nil}

  defp open(%Endpoint{kind: kind, address: address, port: port}) do
    {port, ip} = if kind == :udpin, do: {port, [ip: address]}, else: {0, []}
    family = if tuple_size(address) == 8, do: [:inet6], else: []

    # A fleet's telemetry comes in bursts; a small kernel buffer drops them
    # before we read (the kernel caps this at net.core.rmem_max).
    case :gen_udp.open(port, [:binary, active: 100, recbuf: 4 * 1024 * 1024] ++ ip ++ family) do
      {:ok, socket} -> {:ok, socket}
      {:error, reason} -> {:error, :inet.format_error(reason) |> List.to_string()}
    end
  end

  defp open_forward([]), do: {:ok, nil}

  defp open_forward(endpoints) do
    case Enum.reject(endpoints, &match?(%Endpoint{kind: :udpout}, &1)) do
      [] ->
        {:ok, socket} = :gen_udp.open(0, [:binary, active: false])
        {:ok, {socket, Enum.map(endpoints, &{&1.address, &1.port})}}

      [other | _] ->
        {:error, "can only forward to udpout endpoints, not #{Endpoint.to_string(other)}"}
    end
  end

  defp signing(nil), do: nil

  defp signing(opts) do
    unsigned = if Keyword.get(opts, :require, false), do: :reject, else: :accept
    Signing.new(key: Keyword.fetch!(opts, :key), link_id: Keyword.get(opts, :link_id, 0), unsigned: unsigned)
  end

  @impl true
  # The datagrams already waiting behind this one are taken in the same
  # wake-up (up to @drain_max), and what they hold for each vehicle is
  # handed to its process in one message: under load, several frames per
  # wake-up of a vehicle's process instead of one. Nothing waits for more
  # to come: on a quiet link each datagram is its own batch.
  def handle_info({:udp, socket, ip, port, datagram}, %{socket: socket} = state) do
    {state, routed} = drain(datagram_in(state, ip, port, datagram, []), socket, @drain_max - 1)
    {:noreply, hand_over(state, routed)}
  end

  def handle_info({:udp_passive, socket}, %{socket: socket} = state) do
    :ok = :inet.setopts(socket, active: 100)
    {:noreply, state}
  end

  def handle_info({:tcp, socket, data}, %{socket: socket} = state) do
    forward(state, data)
    # A stream: the parser keeps what a frame split across reads left over.
    before = Parser.stats(state.stream)
    {frames, parser} = Parser.feed(state.stream, data)
    state = %{state | stream: parser, stats: add_stats(state.stats, diff_stats(Parser.stats(parser), before)), signing: parser.signing}
    # (The frames of a read are handed over together, as a wake-up's datagrams are.)
    {state, routed} = deliver(state, frames, :tcp, [])
    {:noreply, hand_over(state, routed)}
  end

  def handle_info({:tcp_passive, socket}, %{socket: socket} = state) do
    :ok = :inet.setopts(socket, active: 100)
    {:noreply, state}
  end

  def handle_info({closed, socket}, %{socket: socket} = state) when closed in [:tcp_closed, :tcp_error] do
    Logger.warning("link #{state.name}: connection closed; reconnecting")
    {:noreply, reconnect(%{state | socket: nil})}
  end

  def handle_info({:tcp_error, socket, reason}, %{socket: socket} = state) do
    Logger.warning("link #{state.name}: #{:inet.format_error(reason)}; reconnecting")
    :gen_tcp.close(socket)
    {:noreply, reconnect(%{state | socket: nil})}
  end

  def handle_info(:connect, %{endpoint: ep} = state) do
    case :gen_tcp.connect(ep.address, ep.port, [:binary, active: 100, nodelay: true], 2_000) do
      {:ok, socket} ->
        Logger.info("link #{state.name}: connected")
        {:noreply, %{state | socket: socket, backoff: @backoff_min, stream: Parser.new(signing: state.signing)}}

      {:error, reason} ->
        Logger.debug("link #{state.name}: cannot connect: #{:inet.format_error(reason)}")
        {:noreply, reconnect(state)}
    end
  end

  def handle_info(:heartbeat, state) do
    Clock.send_after(self(), :heartbeat, @heartbeat_ms)
    heartbeat = %Heartbeat{type: 6, autopilot: 8, base_mode: 0, custom_mode: 0, system_status: 4}
    {:noreply, transmit(state, 0, heartbeat)}
  end

  # Exits of linked sockets (a closed TCP connection) are handled above by
  # their own messages; the parent's exit is handled by GenServer itself.
  def handle_info({:EXIT, _port, _reason}, state), do: {:noreply, state}
  def handle_info(_other, state), do: {:noreply, state}

  @impl true
  def handle_cast({:send, sysid, message}, state), do: {:noreply, transmit(state, sysid, message)}

  @impl true
  def handle_call(:port, _from, %{socket: nil} = state), do: {:reply, nil, state}

  def handle_call(:port, _from, state) do
    {:ok, port} = :inet.port(state.socket)
    {:reply, port, state}
  end

  def handle_call(:info, _from, state),
    do: {:reply, %{stats: state.stats, peers: state.peers, connected: state.socket != nil}, state}

  # The sockets are closed here, not left to the exit of this process: a
  # socket closed by its owner's exit is closed a moment after the exit, and
  # whoever stopped the link (`Dolphin.Link.disconnect/1`) may open the same
  # port again at once. (Trapping exits, a close waits for the port to go.)
  @impl true
  def terminate(_reason, state) do
    close_socket(state.endpoint.kind, state.socket)
    with {socket, _targets} <- state.forward, do: :gen_udp.close(socket)

    with {io, path} <- state.tlog do
      File.close(io)
      Dolphin.Link.Recorded.forget(path, state.name)
    end

    :ok
  end

  defp close_socket(_kind, nil), do: :ok
  defp close_socket(:tcp, socket), do: :gen_tcp.close(socket)
  defp close_socket(_udp, socket), do: :gen_udp.close(socket)

  # Reconnection is in real time, not clock time: it is about the network.
  defp reconnect(state) do
    Process.send_after(self(), :connect, state.backoff)
    %{state | backoff: min(state.backoff * 2, @backoff_max)}
  end

  defp drain({state, routed}, _socket, 0), do: {state, routed}

  defp drain({state, routed}, socket, left) do
    receive do
      {:udp, ^socket, ip, port, datagram} -> drain(datagram_in(state, ip, port, datagram, routed), socket, left - 1)
    after
      0 -> {state, routed}
    end
  end

  # One datagram: forwarded, decoded, its frames recorded and routed (or,
  # with the default router, added to `routed`, newest first).
  defp datagram_in(state, ip, port, datagram, routed) do
    forward(state, datagram)
    # A datagram is whole frames: decode it on its own (a fresh parser, made
    # once: a parser's making costs more than a small frame's decoding), then end it.
    {frames, parser} = Parser.feed(%{state.datagram_parser | signing: state.signing}, datagram)
    {last, parser} = Parser.finish(parser)
    state = %{state | stats: add_stats(state.stats, Parser.stats(parser)), signing: parser.signing}
    deliver(state, frames ++ last, {ip, port}, routed)
  end

  # What the default router was kept for (newest first): to the vehicles, each's in one message.
  defp hand_over(state, []), do: state

  defp hand_over(state, routed) do
    Dolphin.Vehicles.route_all(Enum.reverse(routed))
    state
  end

  defp deliver(state, frames, from, routed) do
    {gcs_sysid, _} = state.gcs

    Enum.reduce(frames, {state, routed}, fn frame, {state, routed} ->
      record_in(state, frame)
      via = {state.name, if(state.endpoint.kind == :udpin, do: from)}

      # A reply addressed to another ground station on the link is not ours.
      routed =
        cond do
          not for_us?(frame.message, gcs_sysid) ->
            routed

          state.batch? ->
            [{frame, via} | routed]

          # (Whatever a router given returns.)
          true ->
            state.router.(frame, via)
            routed
        end

      {heard(state, frame.sysid, from), routed}
    end)
  end

  # Where each system id (and each address) was heard last; most frames
  # change neither, and the maps are not rebuilt for them.
  defp heard(state, _sysid, :tcp), do: state
  defp heard(%{peers: peers} = state, sysid, from) when is_map_key(peers, sysid) and :erlang.map_get(sysid, peers) == from, do: state
  defp heard(state, sysid, from), do: %{state | peers: Map.put(state.peers, sysid, from), heard_from: MapSet.put(state.heard_from, from)}

  defp for_us?(%{target_system: target}, gcs_sysid), do: target in [0, gcs_sysid]
  defp for_us?(_message, _gcs_sysid), do: true

  # What cannot be encoded is a caller's mistake that got this far: it is
  # logged and dropped, never allowed to crash the link (and its vehicles' traffic).
  # `to` is a system id, or {:address, address} for one peer address.
  defp transmit(state, to, message) do
    transmit!(state, to, message)
  rescue
    e in ArgumentError ->
      Logger.error("link #{state.name}: not sent to #{to_text(to)}: #{Exception.message(e)}")
      state
  end

  defp to_text({:address, {ip, port}}), do: "#{:inet.ntoa(ip)}:#{port}"
  defp to_text(sysid), do: "system #{sysid}"

  defp transmit!(state, sysid, message) do
    {gcs_sysid, gcs_compid} = state.gcs
    header = [sysid: gcs_sysid, compid: gcs_compid, seq: state.seq]

    {bytes, state} =
      case state.signing do
        nil ->
          {Frame.encode(message, header), state}

        signing ->
          {bytes, signing} = Signing.encode(signing, message, header)
          {bytes, %{state | signing: signing}}
      end

    deliver_out(state, sysid, bytes)
    forward(state, bytes)
    record(state, bytes)
    %{state | seq: rem(state.seq + 1, 256)}
  end

  defp deliver_out(%{endpoint: %{kind: :tcp}, socket: nil}, _sysid, _bytes), do: :ok

  defp deliver_out(%{endpoint: %{kind: :tcp}, socket: socket} = state, _sysid, bytes) do
    case :gen_tcp.send(socket, bytes) do
      :ok -> :ok
      {:error, reason} -> Logger.debug("link #{state.name}: send failed: #{inspect(reason)}")
    end
  end

  defp deliver_out(state, sysid, bytes) do
    for address <- destinations(state, sysid) do
      case :gen_udp.send(state.socket, address, bytes) do
        :ok -> :ok
        {:error, reason} -> Logger.warning("link #{state.name}: cannot send to #{inspect(address)}: #{:inet.format_error(reason)}")
      end
    end

    :ok
  end

  defp destinations(%{endpoint: %{kind: :udpout} = ep}, _sysid), do: [{ep.address, ep.port}]
  defp destinations(_state, {:address, address}), do: [address]
  defp destinations(%{heard_from: addresses}, 0), do: MapSet.to_list(addresses)

  defp destinations(%{peers: peers}, sysid) do
    case Map.fetch(peers, sysid) do
      {:ok, address} -> [address]
      :error -> []
    end
  end

  defp forward(%{forward: nil}, _bytes), do: :ok
  defp forward(%{forward: {socket, targets}}, bytes), do: Enum.each(targets, fn {ip, port} -> :gen_udp.send(socket, ip, port, bytes) end)

  defp record(%{tlog: nil}, _bytes), do: :ok
  defp record(%{tlog: {io, _path}}, bytes), do: IO.binwrite(io, Tlog.record(System.os_time(:microsecond), bytes))

  # A received frame, unless another link recorded it in the same file (see
  # "Links that share a .tlog").
  defp record_in(%{tlog: nil}, _frame), do: :ok

  defp record_in(%{tlog: {_io, path}, name: name} = state, %Frame{sysid: sysid, compid: compid, seq: seq, raw: raw}) do
    if Dolphin.Link.Recorded.first?(path, {sysid, compid, seq}, raw, name, System.monotonic_time(:millisecond), @copy_window_ms),
      do: record(state, raw),
      else: :ok
  end

  defp add_stats(total, more), do: Stats.combine(total, more, :add)
  defp diff_stats(now, before), do: Stats.combine(now, before, :subtract)
end
