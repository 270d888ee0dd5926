defmodule Dolphin.Web.Hub do
  @moduledoc false
  # One live view's server process, under Dolphin.Web.Supervisor (temporary:
  # a view that ended is not started again, its port and its owner decide):
  # owns the listening socket (its acceptor is a linked Task: shared fate), the bounded model of the run (Web.Live) fed by
  # the vehicles' views and the events, and the list of connected clients,
  # to each of which it sends what changed since what that client last got.

  use GenServer

  alias Dolphin.{Clock, PubSub, Events, Vehicles}
  alias Dolphin.Web.{Connection, Error, Live}

  # How often (real milliseconds) clients are sent what changed: a page
  # redrawn faster than this would only cost the browser. A page that takes
  # long to draw (a long run, near the model's bounds: ~150 ms) is drawn
  # less often, so that the view takes at most a fifth of a core from the
  # fleet: the next frame waits this many times the last drawing's time.
  @frame_ms 250
  @frame_cost 4
  # A client with more frames than this waiting in its connection's mailbox
  # is not sent more: it is behind (a slow network, a stalled browser). What
  # it missed it gets whole once it has caught up, from what it was last sent.
  @max_queue 4
  # Clients at once; more are answered 503.
  @max_clients 100

  @doc false
  # Under Dolphin.Web.Supervisor, not linked to the caller; showing the caller's instance.
  def start(opts), do: DynamicSupervisor.start_child(Dolphin.Web.Supervisor, {__MODULE__, Keyword.put_new(opts, :instance, Dolphin.Instance.current())})

  @doc false
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts, Keyword.take(opts, [:name]))

  @doc false
  def child_spec(opts), do: %{id: __MODULE__, start: {__MODULE__, :start_link, [opts]}, restart: :temporary, shutdown: 15_000}

  @doc false
  # Page n of the view now (binary; a fleet of more than a page's vehicles is shown a page at a time).
  @spec page(pid(), pos_integer()) :: binary()
  def page(hub, n \\ 1), do: GenServer.call(hub, {:page, n}, 15_000)

  @doc false
  # Registers the calling connection, which shows page n; the whole state to send it first.
  @spec subscribe(pid(), pos_integer()) :: {:ok, [{String.t(), binary()}]} | {:error, :busy}
  def subscribe(hub, n \\ 1), do: GenServer.call(hub, {:subscribe, self(), n}, 15_000)

  @impl true
  def init(opts) do
    if instance = opts[:instance], do: Dolphin.Instance.put(instance)
    port = Keyword.fetch!(opts, :port)
    bind = Keyword.get(opts, :bind, "127.0.0.1")

    with {:ok, ip} <- address(bind, port),
         {:ok, listen} <- listen(ip, port, bind) do
      {:ok, actual} = :inet.port(listen)
      hub = self()
      {:ok, _acceptor} = Task.start_link(fn -> accept(listen, hub) end)
      if owner = opts[:owner], do: Process.monitor(owner)
      PubSub.subscribe(:vehicles)
      Events.subscribe()
      origin = Keyword.get(opts, :origin_ms, Clock.now_ms())
      started_at = DateTime.add(DateTime.utc_now(), -Clock.to_real_ms(max(Clock.now_ms() - origin, 0)), :millisecond)
      live = Live.new(origin, [started_at: started_at] ++ Keyword.take(opts, [:title, :tlog]))
      live = opts |> Keyword.get(:history, []) |> Enum.reduce(live, &Live.event(&2, &1))
      # rendered: page number => {page, pieces}, for the pages asked for since the model last changed.
      s = %{listen: listen, port: actual, bind: bind, owner: opts[:owner], live: live, watched: MapSet.new(), unsent: true, rendered: %{}, clients: %{}}
      Process.send_after(self(), :frame, @frame_ms)
      {:ok, Enum.reduce(Vehicles.list(), s, &watch/2)}
    else
      {:error, %Error{} = e} -> {:stop, {:shutdown, e}}
    end
  end

  defp address(bind, port) when is_binary(bind) do
    case :inet.parse_strict_address(String.to_charlist(bind)) do
      {:ok, ip} -> {:ok, ip}
      {:error, _} -> {:error, %Error{reason: :bad_address, address: bind, port: port}}
    end
  end

  defp listen(ip, port, bind) do
    family = if tuple_size(ip) == 8, do: [:inet6], else: []
    # send_timeout: a client that stops reading costs its own connection
    # (closed after this), never the hub, which only ever casts to it.
    options = family ++ [:binary, ip: ip, packet: :http_bin, active: false, reuseaddr: true, backlog: 128, send_timeout: 5_000, send_timeout_close: true]

    case :gen_tcp.listen(port, options) do
      {:ok, listen} -> {:ok, listen}
      {:error, :eaddrinuse} -> {:error, %Error{reason: :address_in_use, address: bind, port: port}}
      {:error, :eaddrnotavail} -> {:error, %Error{reason: :address_not_available, address: bind, port: port}}
      {:error, :eacces} -> {:error, %Error{reason: :permission_denied, address: bind, port: port}}
      {:error, why} -> {:error, %Error{reason: why, address: bind, port: port}}
    end
  end

  # The acceptor: each client gets a process of its own. It ends when the
  # hub's socket closes (the hub stopped).
  defp accept(listen, hub) do
    case :gen_tcp.accept(listen) do
      {:ok, socket} ->
        with {:ok, pid} <- Connection.start(hub),
             :ok <- :gen_tcp.controlling_process(socket, pid) do
          send(pid, {:go, socket})
        else
          _ -> :gen_tcp.close(socket)
        end

        accept(listen, hub)

      {:error, :closed} ->
        :ok

      {:error, _too_many_files_or_such} ->
        # Out of descriptors: wait for some to be freed rather than spin.
        Process.sleep(100)
        accept(listen, hub)
    end
  end

  # Views of a vehicle from now on (once: a vehicle forgotten and found
  # again is discovered again), and the one it has now.
  defp watch(id, s) do
    if MapSet.member?(s.watched, id) do
      s
    else
      Vehicles.subscribe(id)

      case Vehicles.view(id) do
        {:ok, view} -> %{changed(s, Live.view(s.live, view, Clock.now_ms())) | watched: MapSet.put(s.watched, id)}
        {:error, :unknown_vehicle} -> %{s | watched: MapSet.put(s.watched, id)}
      end
    end
  end

  @impl true
  def handle_call({:page, n}, _from, s) do
    {{page, _pieces}, s} = render(s, n)
    {:reply, page, s}
  end

  def handle_call(:port, _from, s), do: {:reply, s.port, s}
  def handle_call(:where, _from, s), do: {:reply, {s.bind, s.port}, s}

  def handle_call({:subscribe, pid, n}, _from, s) do
    if map_size(s.clients) >= @max_clients do
      {:reply, {:error, :busy}, s}
    else
      {{_page, pieces}, s} = render(s, n)
      Process.monitor(pid)
      {:reply, {:ok, pieces}, %{s | clients: Map.put(s.clients, pid, {n, Map.new(pieces)})}}
    end
  end

  @impl true
  def handle_info({:dolphin, :vehicles, {:vehicle_discovered, id}}, s), do: {:noreply, watch(id, s)}

  def handle_info({:dolphin, {:vehicle, _id}, {:view, view}}, s) do
    {:noreply, changed(s, Live.view(s.live, view, Clock.now_ms()))}
  end

  def handle_info({:dolphin, :events, event}, s), do: {:noreply, changed(s, Live.event(s.live, event))}

  def handle_info(:frame, %{unsent: true} = s) when s.clients != %{} do
    started = System.monotonic_time(:millisecond)
    s = push(%{s | unsent: false})
    Process.send_after(self(), :frame, max(@frame_ms, @frame_cost * (System.monotonic_time(:millisecond) - started)))
    {:noreply, s}
  end

  def handle_info(:frame, s) do
    Process.send_after(self(), :frame, @frame_ms)
    {:noreply, s}
  end

  def handle_info({:DOWN, _ref, :process, pid, _why}, %{owner: pid} = s), do: {:stop, :normal, s}
  def handle_info({:DOWN, _ref, :process, pid, _why}, s), do: {:noreply, %{s | clients: Map.delete(s.clients, pid)}}

  def handle_info(_other, s), do: {:noreply, s}

  @impl true
  def terminate(_reason, s), do: :gen_tcp.close(s.listen)

  # The model changed: its pages are drawn again when asked for, and the
  # clients sent what changed at the next frame.
  defp changed(s, live), do: %{s | live: live, rendered: %{}, unsent: true}

  # Page n as the model is now: drawn once per change of the model, whoever asks.
  defp render(s, n) do
    case s.rendered do
      %{^n => rendered} ->
        {rendered, s}

      _ ->
        page = Live.page(s.live, Clock.now_ms(), n)
        rendered = {page, Live.pieces(page)}
        {rendered, %{s | rendered: Map.put(s.rendered, n, rendered)}}
    end
  end

  # Each client gets the pieces of its page that differ from what it was
  # last sent; one that is behind gets nothing now, and all it missed at a
  # later frame.
  defp push(s) do
    Enum.reduce(s.clients, s, fn {pid, {n, sent}}, s ->
      case Process.info(pid, :message_queue_len) do
        {:message_queue_len, queued} when queued <= @max_queue ->
          {{_page, pieces}, s} = render(s, n)

          case for({id, html} <- pieces, Map.get(sent, id) != html, do: {id, html}) do
            [] ->
              s

            changed ->
              send(pid, {:web_frame, changed})
              put_in(s.clients[pid], {n, Map.merge(sent, Map.new(changed))})
          end

        _behind_or_gone ->
          s
      end
    end)
  end
end
