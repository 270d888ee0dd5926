defmodule Dolphin.Test.RadioSplitter do
  @moduledoc """
  Vehicles heard by two radios, on 127.0.0.1: what a vehicle sends reaches two
  ground-station `udpin` endpoints (side `:a` and side `:b`), and what either
  endpoint sends reaches the vehicle. Each side can be cut, delayed or made
  lossy on its own.

      vehicle ──► P (splitter) ──┬── side :a (a Dolphin.Test.UDPProxy) ──► ground station endpoint A
                       ▲         └── side :b (a Dolphin.Test.UDPProxy) ──► ground station endpoint B
                       └──────────── answers from A or B ◄──────────────┘

  The vehicles send to the splitter's port P (`port/1`); the splitter copies
  each datagram to both sides, each from a socket of its own per vehicle (so
  each side sees a distinct source per vehicle, as with two radios), and sends
  what comes back on either side to the vehicle from P. A side is a
  `Dolphin.Test.UDPProxy`, whose impairments it takes as they are:

      {:ok, s} = Dolphin.Test.RadioSplitter.start_link(gcs: [port_a, port_b])
      {:ok, [1]} = Dolphin.Sim.start(count: 1, gcs: Dolphin.Test.RadioSplitter.port(s))
      :ok = Dolphin.Test.RadioSplitter.cut(s, :a)                        # radio A out of range
      :ok = Dolphin.Test.RadioSplitter.set(s, :b, to_gcs: [latency: 80]) # radio B slow
      :ok = Dolphin.Test.RadioSplitter.heal(s, :a)                       # radio A back, clean

  In a test, `start_supervised!({Dolphin.Test.RadioSplitter, gcs: [a, b]})`
  stops it (and closes its sockets) when the test ends. Works on datagrams
  only: no MAVLink parsing.
  """

  use GenServer

  alias Dolphin.Test.UDPProxy

  @localhost {127, 0, 0, 1}
  @sides [:a, :b]
  @clean [loss: 0.0, duplicate: 0.0, reorder: 0.0, latency: 0, jitter: 0]

  @typedoc "A side: the path to one ground-station endpoint."
  @type side :: :a | :b

  @doc """
  Starts a splitter linked to the caller. Options: `:gcs` (required), the
  two ground-station `udpin` ports on 127.0.0.1, side `:a`'s first;
  `:seed` (an integer, default 1) seeds the sides' impairments; `:name`.
  Bad options raise `ArgumentError` in the caller.
  """
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts) do
    case Keyword.keys(opts) -- [:gcs, :seed, :name] do
      [] -> :ok
      unknown -> raise ArgumentError, "RadioSplitter: unknown options #{inspect(unknown)} (known: [:gcs, :seed, :name])"
    end

    gcs =
      case Keyword.fetch(opts, :gcs) do
        {:ok, [a, b]} when a in 1..65_535 and b in 1..65_535 -> [a, b]
        other -> raise ArgumentError, "RadioSplitter :gcs must be two ports [a, b], got: #{inspect(other)}"
      end

    seed = Keyword.get(opts, :seed, 1)
    unless is_integer(seed), do: raise(ArgumentError, "RadioSplitter :seed must be an integer, got: #{inspect(seed)}")
    GenServer.start_link(__MODULE__, {gcs, seed}, Keyword.take(opts, [:name]))
  end

  @doc "The port vehicles send to, on 127.0.0.1."
  @spec port(GenServer.server()) :: :inet.port_number()
  def port(splitter), do: GenServer.call(splitter, :port)

  @doc """
  Changes one side's impairments: `changes` as for `Dolphin.Test.UDPProxy.set/2`
  (`to_gcs:`, `to_vehicle:`, `both:`).
  """
  @spec set(GenServer.server(), side(), keyword()) :: :ok
  def set(splitter, side, changes) when side in @sides, do: UDPProxy.set(proxy(splitter, side), changes)

  @doc "Cuts one side both ways (every datagram lost)."
  @spec cut(GenServer.server(), side()) :: :ok
  def cut(splitter, side), do: set(splitter, side, both: [loss: 1.0])

  @doc "Makes one side clean again both ways (no loss, delay, duplication or reordering)."
  @spec heal(GenServer.server(), side()) :: :ok
  def heal(splitter, side), do: set(splitter, side, both: @clean)

  @doc "One side's counters and impairments (`Dolphin.Test.UDPProxy.stats/1`)."
  @spec stats(GenServer.server(), side()) :: map()
  def stats(splitter, side) when side in @sides, do: UDPProxy.stats(proxy(splitter, side))

  @doc "Stops the splitter, its sides and their sockets."
  @spec stop(GenServer.server()) :: :ok
  def stop(splitter), do: GenServer.stop(splitter)

  defp proxy(splitter, side), do: GenServer.call(splitter, {:proxy, side})

  @impl true
  def init({gcs, seed}) do
    # Trapping exits lets terminate/2 close the sockets when the parent stops us.
    Process.flag(:trap_exit, true)
    # The network, at the links' priority (see Dolphin.Test.UDPProxy).
    Process.flag(:priority, :high)

    with {:ok, socket} <- :gen_udp.open(0, socket_opts()),
         {:ok, port} <- :inet.port(socket) do
      proxies =
        @sides
        |> Enum.zip(gcs)
        |> Enum.with_index()
        |> Map.new(fn {{side, gcs_port}, i} ->
          {:ok, proxy} = UDPProxy.start_link(gcs: gcs_port, seed: seed + i)
          {side, %{proxy: proxy, port: UDPProxy.port(proxy)}}
        end)

      # vehicle address => %{side => socket}, and socket => vehicle address
      {:ok, %{socket: socket, port: port, proxies: proxies, vehicles: %{}, owner: %{}}}
    else
      {:error, why} -> {:stop, "RadioSplitter: cannot open a socket: #{:inet.format_error(why)}"}
    end
  end

  # As Dolphin.Test.UDPProxy: a hundred datagrams at a time, re-armed on :udp_passive.
  defp socket_opts, do: [:binary, active: 100, ip: @localhost, recbuf: 4 * 1024 * 1024]

  @impl true
  def handle_call(:port, _from, s), do: {:reply, s.port, s}
  def handle_call({:proxy, side}, _from, s), do: {:reply, s.proxies[side].proxy, s}

  @impl true
  # From a vehicle: a copy to each side.
  def handle_info({:udp, socket, ip, port, bytes}, %{socket: socket} = s) do
    {sockets, s} = sockets(s, {ip, port})
    for {side, side_socket} <- sockets, do: :gen_udp.send(side_socket, @localhost, s.proxies[side].port, bytes)
    {:noreply, s}
  end

  # From a side: to the vehicle it answers.
  def handle_info({:udp, side_socket, _ip, _port, bytes}, s) do
    with {:ok, {ip, port}} <- Map.fetch(s.owner, side_socket), do: :gen_udp.send(s.socket, ip, port, bytes)
    {:noreply, s}
  end

  def handle_info({:udp_passive, socket}, s) do
    :ok = :inet.setopts(socket, active: 100)
    {:noreply, s}
  end

  def handle_info({:EXIT, _from, reason}, s), do: {:stop, reason, s}

  @impl true
  # The sides are linked and trap exits: they stop with us.
  def terminate(_reason, s) do
    :gen_udp.close(s.socket)
    for {socket, _vehicle} <- s.owner, do: :gen_udp.close(socket)
    :ok
  end

  defp sockets(s, vehicle) do
    case s.vehicles do
      %{^vehicle => sockets} ->
        {sockets, s}

      _ ->
        sockets = Map.new(@sides, fn side -> {side, elem(:gen_udp.open(0, socket_opts()), 1)} end)
        owner = Enum.reduce(sockets, s.owner, fn {_side, socket}, owner -> Map.put(owner, socket, vehicle) end)
        {sockets, %{s | vehicles: Map.put(s.vehicles, vehicle, sockets), owner: owner}}
    end
  end
end
