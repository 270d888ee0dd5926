defmodule Dolphin.Test.UDPProxy do
  @moduledoc """
  A UDP proxy on 127.0.0.1 that impairs the traffic between a ground station
  and vehicles that talk MAVLink over UDP: it loses, duplicates, reorders and
  delays datagrams, each way on its own settings, from a seeded generator.

  The topology is ArduPilot SITL's (`--serial0 udpclient:127.0.0.1:P`): the
  vehicles send to the proxy's port P; the proxy forwards what each vehicle
  sends to the ground station's `udpin` port from one socket per vehicle
  source address (so the ground station sees a distinct source per vehicle and
  answers to it), and sends the ground station's answers back to that
  vehicle's address from P. Several vehicles share P.

      vehicle A ──┐                 ┌── socket for A ──┐
                  ├─► P (proxy) ────┤                  ├─► ground station (udpin G)
      vehicle B ──┘                 └── socket for B ──┘

  It works on datagrams (no MAVLink parsing):

      {:ok, link} = Dolphin.Link.connect("udpin:127.0.0.1:0", name: "gcs")
      {:ok, proxy} = Dolphin.Test.UDPProxy.start_link(gcs: Dolphin.Link.Connection.port("gcs"), seed: 7,
                                                       both: [loss: 0.2, duplicate: 0.05, reorder: 0.05])
      {:ok, [1]} = Dolphin.Sim.start(count: 1, gcs: Dolphin.Test.UDPProxy.port(proxy))
      :ok = Dolphin.Test.UDPProxy.set(proxy, to_vehicle: [loss: 1.0])   # the uplink dies
      %{to_gcs: %{received: _, dropped: _}} = Dolphin.Test.UDPProxy.stats(proxy)

  In a test, `start_supervised!({Dolphin.Test.UDPProxy, gcs: port})` stops it
  (and closes its sockets) when the test ends.

  ## Impairments

  Per direction, `to_gcs` (what vehicles send) and `to_vehicle` (the ground
  station's answers), given as a keyword list or map:

  | key | meaning | default |
  | --- | --- | --- |
  | `loss` | probability that a datagram is dropped | 0 |
  | `duplicate` | probability that a forwarded datagram is sent twice | 0 |
  | `reorder` | probability that a datagram is held back and sent just after the next one on the same vehicle's path, or after `reorder_ms` if none comes | 0 |
  | `reorder_ms` | the longest a held-back datagram waits, real ms | 20 |
  | `latency` | real milliseconds every datagram takes | 0 |
  | `jitter` | up to this many more real milliseconds, uniform (datagrams may then overtake each other) | 0 |

  Delays are wall-clock network delays (`Process.send_after/3`), not
  `Dolphin.Clock` time: a link's delay does not shrink with the simulation's
  speed-up.

  Randomness: the proxy process seeds its own `:rand` state
  (`:rand.seed(:exsss, seed)`) and draws the same numbers per datagram
  whatever the settings, so the same seed and the same datagrams in the same
  order give the same faults.

  ## Counters

  `stats/1` gives, per direction:

    * `received` — datagrams read;
    * `forwarded` — datagrams sent on, duplicates included;
    * `dropped` — lost on purpose;
    * `duplicated` — extra copies made;
    * `reordered` — held back (most go out after a later one; one with nothing
      after it within `reorder_ms` goes out late but in place);
    * `pending` — held back or waiting for their delay, not yet sent;
    * `send_errors` — sends the socket refused;

  and `vehicles`, the number of vehicle addresses seen, and `impairments`, the
  current settings. Once nothing is pending, in each direction
  `forwarded + send_errors == received - dropped + duplicated`.
  """

  use GenServer

  @localhost {127, 0, 0, 1}
  @keys [:loss, :duplicate, :reorder, :reorder_ms, :latency, :jitter]
  @counters %{received: 0, forwarded: 0, dropped: 0, duplicated: 0, reordered: 0, send_errors: 0}

  @typedoc "A direction's impairments (see the moduledoc's table)."
  @type impairments :: [
          loss: float(),
          duplicate: float(),
          reorder: float(),
          reorder_ms: non_neg_integer(),
          latency: non_neg_integer(),
          jitter: non_neg_integer()
        ]

  @typedoc "A vehicle's source address."
  @type address :: {:inet.ip_address(), :inet.port_number()}

  @doc """
  Starts a proxy linked to the caller. Options:

    * `:gcs` (required) — the ground station's `udpin` port on 127.0.0.1, or `{ip, port}`;
    * `:port` — the port vehicles send to (default 0, an ephemeral port: see `port/1`);
    * `:seed` — seeds the impairments' randomness (an integer or a 3-tuple of integers; default 1);
    * `:to_gcs`, `:to_vehicle` — each direction's impairments; `:both` — the same for both
      (applied first, so `:to_gcs`/`:to_vehicle` override it key by key);
    * `:name` — a name to register the process under.

  Bad options raise `ArgumentError` in the caller.
  """
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts) do
    config = validate!(opts)
    GenServer.start_link(__MODULE__, config, Keyword.take(opts, [:name]))
  end

  @doc "The port vehicles send to, on 127.0.0.1."
  @spec port(GenServer.server()) :: :inet.port_number()
  def port(proxy), do: GenServer.call(proxy, :port)

  @doc """
  Changes impairments at run time: `to_gcs:`, `to_vehicle:` or `both:` with the
  keys to change (the others keep their values). Datagrams already held back or
  delayed keep their fate. Bad settings raise `ArgumentError` in the caller.
  """
  @spec set(GenServer.server(), keyword()) :: :ok
  def set(proxy, changes) do
    only!(changes, [:to_gcs, :to_vehicle, :both])
    GenServer.call(proxy, {:set, directions!(changes, %{})})
  end

  @doc "The counters (see the moduledoc) and the current impairments."
  @spec stats(GenServer.server()) :: %{to_gcs: map(), to_vehicle: map(), vehicles: non_neg_integer(), impairments: map()}
  def stats(proxy), do: GenServer.call(proxy, :stats)

  @doc "The vehicle addresses seen, each with the port of the socket that speaks for it to the ground station."
  @spec vehicles(GenServer.server()) :: [{address(), :inet.port_number()}]
  def vehicles(proxy), do: GenServer.call(proxy, :vehicles)

  @doc "Stops the proxy and closes its sockets."
  @spec stop(GenServer.server()) :: :ok
  def stop(proxy), do: GenServer.stop(proxy)

  # --- configuration, validated once in the caller ---

  @defaults %{loss: 0.0, duplicate: 0.0, reorder: 0.0, reorder_ms: 20, latency: 0, jitter: 0}

  defp validate!(opts) do
    only!(opts, [:gcs, :port, :seed, :to_gcs, :to_vehicle, :both, :name])

    gcs =
      case Keyword.fetch(opts, :gcs) do
        {:ok, port} when is_integer(port) and port in 1..65_535 -> {@localhost, port}
        {:ok, {ip, port}} when is_tuple(ip) and is_integer(port) and port in 1..65_535 -> {ip, port}
        {:ok, other} -> raise ArgumentError, "UDPProxy :gcs must be a port (1..65535) or {ip, port}, got: #{inspect(other)}"
        :error -> raise ArgumentError, "UDPProxy: the :gcs option (the ground station's udpin port) is required"
      end

    port =
      case Keyword.get(opts, :port, 0) do
        p when is_integer(p) and p in 0..65_535 -> p
        other -> raise ArgumentError, "UDPProxy :port must be 0..65535, got: #{inspect(other)}"
      end

    seed =
      case Keyword.get(opts, :seed, 1) do
        s when is_integer(s) -> s
        {a, b, c} = s when is_integer(a) and is_integer(b) and is_integer(c) -> s
        other -> raise ArgumentError, "UDPProxy :seed must be an integer or a 3-tuple of integers, got: #{inspect(other)}"
      end

    %{gcs: gcs, port: port, seed: seed, impairments: directions!(opts, @defaults)}
  end

  defp only!(opts, known) do
    unless Keyword.keyword?(opts), do: raise(ArgumentError, "UDPProxy options must be a keyword list, got: #{inspect(opts)}")

    case Keyword.keys(opts) -- known do
      [] -> :ok
      unknown -> raise ArgumentError, "UDPProxy: unknown options #{inspect(unknown)} (known: #{inspect(known)})"
    end
  end

  # Each direction's settings: `base` completed by `:both`, then by the direction's own.
  defp directions!(opts, base) do
    both = settings!(:both, Keyword.get(opts, :both, []))
    Map.new([:to_gcs, :to_vehicle], fn dir -> {dir, base |> Map.merge(both) |> Map.merge(settings!(dir, Keyword.get(opts, dir, [])))} end)
  end

  defp settings!(dir, settings) when is_list(settings) or is_map(settings) do
    Map.new(settings, fn
      {key, p} when key in [:loss, :duplicate, :reorder] and is_number(p) and p >= 0 and p <= 1 ->
        {key, p * 1.0}

      {key, ms} when key in [:reorder_ms, :latency, :jitter] and is_integer(ms) and ms >= 0 ->
        {key, ms}

      {key, value} ->
        raise ArgumentError,
              "UDPProxy #{inspect(dir)}: bad impairment #{inspect(key)}: #{inspect(value)} " <>
                "(known: #{inspect(@keys)}; probabilities 0..1, times in whole ms >= 0)"
    end)
  end

  defp settings!(dir, other), do: raise(ArgumentError, "UDPProxy #{inspect(dir)}: impairments must be a keyword list or a map, got: #{inspect(other)}")

  # --- the process ---

  @impl true
  def init(config) do
    # Trapping exits lets terminate/2 close the sockets when the parent (a test
    # process or a supervisor) stops us.
    Process.flag(:trap_exit, true)
    # It plays the network, which a busy BEAM does not slow: at high priority,
    # as the ground station's links are (at normal priority, one of a radio
    # splitter's two sides fell 0.75 s behind the other on a loaded host, and
    # the ground station rightly judged its path silent).
    Process.flag(:priority, :high)
    :rand.seed(:exsss, config.seed)

    case :gen_udp.open(config.port, socket_opts()) do
      {:ok, socket} ->
        {:ok, port} = :inet.port(socket)

        {:ok,
         %{
           socket: socket,
           port: port,
           gcs: config.gcs,
           impairments: config.impairments,
           # vehicle address => upstream socket, and back
           upstream: %{},
           owner: %{},
           # {direction, vehicle address} => held-back datagrams, oldest first,
           # as {ref, delay, copies} (copies: [{route, bytes}], two when duplicated)
           held: %{},
           # per direction, copies in timer messages not yet sent
           in_flight: %{to_gcs: 0, to_vehicle: 0},
           stats: %{to_gcs: @counters, to_vehicle: @counters}
         }}

      {:error, why} ->
        {:stop, "UDPProxy: cannot open 127.0.0.1:#{config.port}: #{:inet.format_error(why)}"}
    end
  end

  # Active a hundred datagrams at a time (re-armed on :udp_passive), as the
  # links do: a burst cannot flood the mailbox faster than we forward.
  defp socket_opts, do: [:binary, active: 100, ip: @localhost, recbuf: 4 * 1024 * 1024]

  @impl true
  def handle_call(:port, _from, s), do: {:reply, s.port, s}

  def handle_call({:set, changes}, _from, s) do
    impairments = Map.new(s.impairments, fn {dir, current} -> {dir, Map.merge(current, changes[dir])} end)
    {:reply, :ok, %{s | impairments: impairments}}
  end

  def handle_call(:stats, _from, s) do
    counters = Map.new(s.stats, fn {dir, counters} -> {dir, Map.put(counters, :pending, pending(s, dir))} end)
    {:reply, Map.merge(counters, %{vehicles: map_size(s.upstream), impairments: s.impairments}), s}
  end

  def handle_call(:vehicles, _from, s) do
    {:reply, for({address, socket} <- s.upstream, do: {address, elem(:inet.port(socket), 1)}), s}
  end

  @impl true
  def handle_info({:udp, socket, ip, port, bytes}, %{socket: socket} = s) do
    {upstream, s} = upstream(s, {ip, port})
    {:noreply, arrive(s, :to_gcs, {ip, port}, {upstream, s.gcs}, bytes)}
  end

  def handle_info({:udp, upstream, _ip, _port, bytes}, s) do
    %{^upstream => vehicle} = s.owner
    {:noreply, arrive(s, :to_vehicle, vehicle, {s.socket, vehicle}, bytes)}
  end

  def handle_info({:udp_passive, socket}, s) do
    :ok = :inet.setopts(socket, active: 100)
    {:noreply, s}
  end

  def handle_info({:deliver, dir, copies}, s) do
    s = update_in(s, [:in_flight, dir], &(&1 - length(copies)))
    {:noreply, Enum.reduce(copies, s, &transmit(&2, dir, &1))}
  end

  def handle_info({:release, {dir, _vehicle} = path, ref}, s) do
    case List.keytake(Map.get(s.held, path, []), ref, 0) do
      {{^ref, delay, copies}, rest} -> {:noreply, s |> hold(path, rest) |> send_out(dir, delay, copies)}
      # Already sent, just after a later datagram.
      nil -> {:noreply, s}
    end
  end

  def handle_info({:EXIT, _from, reason}, s), do: {:stop, reason, s}

  @impl true
  def terminate(_reason, s) do
    :gen_udp.close(s.socket)
    Enum.each(s.upstream, fn {_vehicle, socket} -> :gen_udp.close(socket) end)
  end

  defp upstream(s, vehicle) do
    case s.upstream do
      %{^vehicle => socket} ->
        {socket, s}

      _ ->
        {:ok, socket} = :gen_udp.open(0, socket_opts())
        {socket, %{s | upstream: Map.put(s.upstream, vehicle, socket), owner: Map.put(s.owner, socket, vehicle)}}
    end
  end

  # One datagram in. Four draws always (loss, reorder, duplicate, jitter), so
  # the sequence of draws depends only on the datagrams, not on the settings
  # nor on when timers fire.
  defp arrive(s, dir, vehicle, route, bytes) do
    imp = s.impairments[dir]
    [lost, late, twice, jitter] = for _ <- 1..4, do: :rand.uniform()
    s = count(s, dir, :received, 1)
    delay = imp.latency + round(jitter * imp.jitter)
    copies = if twice < imp.duplicate, do: [{route, bytes}, {route, bytes}], else: [{route, bytes}]
    path = {dir, vehicle}
    held = Map.get(s.held, path, [])

    cond do
      lost < imp.loss ->
        count(s, dir, :dropped, 1)

      late < imp.reorder ->
        ref = make_ref()
        Process.send_after(self(), {:release, path, ref}, imp.reorder_ms)

        s
        |> hold(path, held ++ [{ref, delay, copies}])
        |> count(dir, :reordered, 1)
        |> count(dir, :duplicated, length(copies) - 1)

      true ->
        # What was held back on this vehicle's path goes out just after this
        # one, in the same timer message: nothing can come between them.
        behind = Enum.flat_map(held, fn {_ref, _delay, held_copies} -> held_copies end)

        s
        |> hold(path, [])
        |> count(dir, :duplicated, length(copies) - 1)
        |> send_out(dir, delay, copies ++ behind)
    end
  end

  defp send_out(s, dir, 0, copies), do: Enum.reduce(copies, s, &transmit(&2, dir, &1))

  defp send_out(s, dir, delay, copies) do
    Process.send_after(self(), {:deliver, dir, copies}, delay)
    update_in(s, [:in_flight, dir], &(&1 + length(copies)))
  end

  defp transmit(s, dir, {{socket, {ip, port}}, bytes}) do
    case :gen_udp.send(socket, ip, port, bytes) do
      :ok -> count(s, dir, :forwarded, 1)
      {:error, _} -> count(s, dir, :send_errors, 1)
    end
  end

  defp hold(s, path, []), do: %{s | held: Map.delete(s.held, path)}
  defp hold(s, path, held), do: %{s | held: Map.put(s.held, path, held)}

  # Copies held back or waiting for their delay, not yet sent.
  defp pending(s, dir) do
    held = for {{^dir, _vehicle}, list} <- s.held, {_ref, _delay, copies} <- list, reduce: 0, do: (n -> n + length(copies))
    held + s.in_flight[dir]
  end

  defp count(s, _dir, _counter, 0), do: s
  defp count(s, dir, counter, n), do: update_in(s, [:stats, dir, counter], &(&1 + n))
end
