defmodule Dolphin.Vehicles.Routes do
  @moduledoc """
  Where to reach the vehicles this node has no process of: a vehicle heard by
  another ground station (`Dolphin.Cluster`) is reached through that
  station's vehicle process, and `Dolphin.Vehicles.whereis/1` falls back to
  the route kept here when no local process has the id (a local vehicle of
  the same id always wins).

  A route is written by its *router*, the process that decides it (the
  cluster's `Dolphin.Cluster.Mirror`), with `put/2` and `delete/1`. The
  vehicles layer asks the router again through two calls it answers, so
  that this layer knows nothing of what routes mean above it:

    * `{:reroute, id, dead}` — a call to `dead` (the route) exited for want
      of its node: the route now, or nil (`reroute/2`);
    * `{:forget, id}` — forget the vehicle here (`forget/1`).

  The table is public (a route is read on every command, without a call)
  and owned by this small process, which monitors every router: a router
  that ends takes its routes with it, so no command goes to a route nobody
  keeps any more.
  """

  use GenServer

  @doc false
  # Started by its Dolphin.Instance, which names it.
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, Keyword.fetch!(opts, :name), name: Keyword.fetch!(opts, :name))

  @doc "The process a vehicle's commands go to when this node has none of its own, or nil."
  @spec get(non_neg_integer()) :: pid() | nil
  def get(id) do
    case :ets.lookup(table(), id) do
      [{^id, pid, _router}] -> pid
      [] -> nil
    end
  rescue
    # The table is being restarted with its owner.
    ArgumentError -> nil
  end

  @doc """
  Routes vehicle `id` to `pid`; the caller is its router (see the module
  doc), and its routes go when it ends.
  """
  @spec put(non_neg_integer(), pid()) :: :ok
  def put(id, pid) when is_pid(pid) do
    :ok = GenServer.call(table(), {:router, self()})
    :ets.insert(table(), {id, pid, self()})
    :ok
  end

  @doc "Removes the route of vehicle `id`."
  @spec delete(non_neg_integer()) :: :ok
  def delete(id) do
    :ets.delete(table(), id)
    :ok
  end

  @doc """
  After a call to `dead`, the route of vehicle `id`, exited because its node
  went away: the route the router has now (it settles the node's departure
  first if it had not heard of it), or nil.
  """
  @spec reroute(non_neg_integer(), pid()) :: pid() | nil
  def reroute(id, dead) do
    case router(id) do
      nil -> nil
      router -> GenServer.call(router, {:reroute, id, dead}, 10_000)
    end
  catch
    :exit, _ -> nil
  end

  @doc "Has the router of vehicle `id` forget it here; `:ok` also when it has no route."
  @spec forget(non_neg_integer()) :: :ok
  def forget(id) do
    case router(id) do
      nil -> :ok
      router -> GenServer.call(router, {:forget, id})
    end
  end

  defp router(id) do
    case :ets.lookup(table(), id) do
      [{^id, _pid, router}] -> router
      [] -> nil
    end
  end

  @impl true
  def init(table) do
    :ets.new(table, [:named_table, :public, :set, read_concurrency: true])
    {:ok, %{routers: %{}}}
  end

  @impl true
  def handle_call({:router, pid}, _from, s) do
    if Map.has_key?(s.routers, pid) do
      {:reply, :ok, s}
    else
      {:reply, :ok, put_in(s.routers[pid], Process.monitor(pid))}
    end
  end

  @impl true
  def handle_info({:DOWN, _ref, :process, pid, _reason}, s) do
    :ets.match_delete(table(), {:_, :_, pid})
    {:noreply, %{s | routers: Map.delete(s.routers, pid)}}
  end

  defp table, do: Dolphin.Instance.names().routes
end
