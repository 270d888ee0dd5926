defmodule Dolphin.Cluster do
  @moduledoc """
  Several ground stations, one fleet, on distributed Erlang.

  Every node runs a `Dolphin.Cluster.Station` (it tells controllers about the
  vehicles this node hears) and a `Dolphin.Cluster.Mirror` (it makes the
  vehicles of joined stations appear here). Both live in the `:pg` scope
  `#{inspect(Dolphin.Cluster.Scope)}`, started in the application's tree.

      # a station: links and vehicles, no script
      {:ok, _} = Dolphin.Cluster.start_node("gs1", :shortnames, "secret")
      # a controller
      {:ok, _} = Dolphin.Cluster.start_node("ctl", :shortnames, "secret")
      :ok = Dolphin.Cluster.join(:"gs1@myhost")
      Dolphin.Vehicles.list()        # the vehicles of gs1 too

  `join/2` connects to the node, checks the speed-up (a node with no
  speed-up of its own adopts the station's; a different one is refused),
  and subscribes the mirror to the node's station; a joined node that goes
  away is reconnected to until it comes back. See `docs/cluster.md` for
  what is routed where, the failover rules, conflicts and netsplits.
  """

  alias Dolphin.Cluster.{Error, Mirror}

  @doc "The `:pg` scope of Dolphin's process groups (stations, fleets)."
  @spec scope() :: atom()
  def scope, do: Dolphin.Cluster.Scope

  @doc "Whether this node is part of a cluster now (distribution started and at least one other node connected)."
  @spec clustered?() :: boolean()
  def clustered?, do: Node.alive?() and Node.list() != []

  @doc """
  Starts distribution on this node as `name` (`:shortnames` for `--sname`,
  `:longnames` for `--name`), with `cookie` when given; starts EPMD first if
  none runs (bound to `ERL_EPMD_ADDRESS` when set, as EPMD itself reads it).
  A node that is distributed already (`iex --sname op -S mix ...`) keeps
  the name it has.
  """
  @spec start_node(String.t(), :shortnames | :longnames, String.t() | nil) :: {:ok, node()} | {:error, Error.t()}
  def start_node(name, type, cookie \\ nil) when type in [:shortnames, :longnames] do
    result =
      cond do
        Node.alive?() -> {:ok, node()}
        true -> with :ok <- ensure_epmd(), do: net_start(name, type)
      end

    with {:ok, node} <- result do
      if cookie, do: Node.set_cookie(String.to_atom(cookie))
      {:ok, node}
    end
  end

  defp net_start(name, type) do
    case Node.start(String.to_atom(name), type) do
      {:ok, _} ->
        {:ok, node()}

      {:error, reason} ->
        {:error, %Error{reason: :distribution, node: name, detail: "cannot start distribution as #{name}: #{inspect(reason)}"}}
    end
  end

  # EPMD is how nodes find each other's distribution port; Node.start/2 needs one.
  defp ensure_epmd do
    case :erl_epmd.names() do
      {:ok, _} ->
        :ok

      {:error, _} ->
        case System.find_executable("epmd") do
          nil ->
            {:error, %Error{reason: :distribution, detail: "no EPMD runs and no epmd executable was found to start one"}}

          epmd ->
            {_, 0} = System.cmd(epmd, ["-daemon"])
            wait_epmd(50)
        end
    end
  end

  # Only the default instance is part of a cluster: its mirror is the one
  # that follows other stations, its fleet the one that claims.
  defp in_cluster_instance(node) do
    instance = Dolphin.Instance.current()

    if instance == Dolphin.Instance.default() do
      :ok
    else
      detail = "cannot join #{node} from instance #{inspect(instance)}: only the default instance (#{inspect(Dolphin.Instance.default())}) is part of a cluster"
      {:error, %Error{reason: :not_cluster_instance, node: node, detail: detail}}
    end
  end

  defp wait_epmd(0), do: {:error, %Error{reason: :distribution, detail: "EPMD was started but does not answer"}}

  defp wait_epmd(n) do
    case :erl_epmd.names() do
      {:ok, _} -> :ok
      {:error, _} ->
        Process.sleep(20)
        wait_epmd(n - 1)
    end
  end

  @doc """
  Joins the ground station `node`: connects, checks the speed-up, follows its
  station. Options: `:speedup` — this node's own speed-up as the user gave it
  (nil: adopt the station's); `:timeout_ms` — how long to wait for the
  node's station (default 5 s).
  """
  @spec join(node() | String.t(), keyword()) :: :ok | {:error, Error.t()}
  def join(node, opts \\ []) do
    node = if is_binary(node), do: String.to_atom(node), else: node

    with :ok <- in_cluster_instance(node),
         :ok <- alive(node),
         :ok <- connect(node),
         :ok <- agree_speedup(node, opts[:speedup]) do
      case Mirror.follow(node, Keyword.get(opts, :timeout_ms, 5_000)) do
        :ok -> :ok
        {:error, :no_station} -> {:error, %Error{reason: :no_station, node: node, detail: "#{node} runs no Dolphin ground station"}}
      end
    end
  end

  defp alive(node) do
    if Node.alive?(),
      do: :ok,
      else: {:error, %Error{reason: :not_distributed, node: node, detail: "this node has no name: start it with --sname or --name to join #{node}"}}
  end

  defp connect(node) do
    case Node.connect(node) do
      true -> :ok
      _ -> {:error, why_unreachable(node)}
    end
  end

  # A node cannot tell a wrong cookie for sure (the other side just closes
  # the connection): if EPMD on the host knows the name, the node is there
  # and refused us, which is what a different cookie does.
  defp why_unreachable(node) do
    case String.split(Atom.to_string(node), "@", parts: 2) do
      [name, host] ->
        case :erl_epmd.names(String.to_charlist(host)) do
          {:ok, names} ->
            if Enum.any?(names, fn {n, _port} -> List.to_string(n) == name end),
              do: %Error{reason: :refused, node: node, detail: "cannot reach #{node}: the connection was refused (the cookies may differ; a node cannot tell for sure)"},
              else: %Error{reason: :unreachable, node: node, detail: "cannot reach #{node}: no node named #{name} is registered with EPMD on #{host}"}

          {:error, why} ->
            %Error{reason: :unreachable, node: node, detail: "cannot reach #{node}: EPMD on #{host} does not answer (#{inspect(why)})"}
        end

      _ ->
        %Error{reason: :unreachable, node: node, detail: "cannot reach #{node}: a node name is name@host"}
    end
  end

  defp agree_speedup(node, mine) do
    case :erpc.call(node, Dolphin.Clock, :speedup, [], 5_000) do
      theirs when mine == nil ->
        Dolphin.Clock.set_speedup(theirs)

      theirs when theirs == mine ->
        Dolphin.Clock.set_speedup(mine)

      theirs ->
        {:error, %Error{reason: :speedup, node: node, detail: "#{node} runs at speed-up #{format(theirs)}, this node was asked for #{format(mine)}: a cluster has one speed-up (leave --speedup out to adopt the station's)"}}
    end
  catch
    :error, {:erpc, why} -> {:error, %Error{reason: :unreachable, node: node, detail: "cannot reach #{node}: #{inspect(why)}"}}
    :error, {:exception, :undef, _} -> {:error, %Error{reason: :no_station, node: node, detail: "#{node} runs no Dolphin ground station"}}
  end

  defp format(k) when is_float(k) and k == trunc(k), do: Integer.to_string(trunc(k))
  defp format(k), do: to_string(k)
end
