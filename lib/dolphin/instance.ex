defmodule Dolphin.Instance do
  @moduledoc """
  A ground station's vehicle layer as one supervised unit: its vehicles and
  their views, its links, its publish/subscribe, its fleet, its simulated
  and SITL vehicles, and its clock's speed-up. The application starts one,
  the default instance `Dolphin`; a test (or anything that wants a fleet of
  its own in the same BEAM) starts another under its own name, and what
  happens in one is not seen in the other: two instances can both have a
  vehicle 1, and fly at different speed-ups.

      {:ok, _} = Dolphin.Instance.start_link(name: :bench)
      Dolphin.Instance.put(:bench)          # this process works in :bench now
      Dolphin.Clock.set_speedup(50)         # :bench's clock, not Dolphin's

  Every process belongs to one instance (`current/0`): the one it was put in
  (`put/1`; an engine run puts the one its `Dolphin.Engine.Context` names),
  else the one of the process that started it (its `$callers`, then its
  `$ancestors`, as a `Task` or a supervised child records them), else the
  default. So a vehicle's process, started under an instance's supervisor,
  and a task a test starts, work in their instance without being told.

  The instance's parts are named from its name (`names/1`); the default's
  names are the modules' own (`Dolphin.PubSub`, `Dolphin.Vehicles.Views`,
  ...).
  """

  use Supervisor

  @default Dolphin
  @key :"$dolphin_instance"

  defmodule Names do
    @moduledoc """
    The registered names of an instance's parts (see `Dolphin.Instance.names/1`).
    """
    @enforce_keys [:instance, :registry, :pubsub, :views, :heard, :paths, :routes, :settings, :vehicles, :links, :fleet, :separation, :sims, :sitls, :cluster?]
    defstruct @enforce_keys

    @type t :: %__MODULE__{}
  end

  @parts [
    registry: Dolphin.Registry,
    pubsub: Dolphin.PubSub,
    views: Dolphin.Vehicles.Views,
    heard: Dolphin.Vehicles.Views.Heard,
    paths: Dolphin.Vehicles.Views.Paths,
    routes: Dolphin.Vehicles.Routes,
    settings: Dolphin.Vehicles.Settings,
    vehicles: Dolphin.Vehicles.Supervisor,
    links: Dolphin.Link.Supervisor,
    fleet: Dolphin.Fleet,
    separation: Dolphin.Separation,
    sims: Dolphin.Sim.Supervisor,
    sitls: Dolphin.SITL.Supervisor
  ]

  @doc "The default instance, the one the application starts."
  @spec default() :: atom()
  def default, do: @default

  @doc """
  Starts an instance. Options: `:name` (an atom, required), `:cluster`
  (true: it is the node's part of a cluster of ground stations — its fleet
  claims vehicles cluster-wide and other stations' vehicles are mirrored
  into it; only the default instance is), `:links` (true: the links of the
  application's configuration are opened in it).
  """
  @spec start_link(keyword()) :: Supervisor.on_start()
  def start_link(opts) do
    name = Keyword.fetch!(opts, :name)
    unless is_atom(name) and name != nil, do: raise(ArgumentError, "an instance's name is an atom, got: #{inspect(name)}")
    Supervisor.start_link(__MODULE__, opts, name: supervisor_name(name))
  end

  @doc false
  def child_spec(opts), do: %{id: {__MODULE__, Keyword.fetch!(opts, :name)}, start: {__MODULE__, :start_link, [opts]}, type: :supervisor}

  @doc "Stops instance `name` and everything in it."
  @spec stop(atom()) :: :ok
  def stop(name) do
    Supervisor.stop(supervisor_name(name))
    :ok
  end

  @doc """
  The instance the calling process works in (see the module doc).

      iex> Dolphin.Instance.current()
      Dolphin
  """
  @spec current() :: atom()
  def current do
    case Process.get(@key) do
      nil ->
        instance = inherited()
        Process.put(@key, instance)
        instance

      instance ->
        instance
    end
  end

  @doc "Makes `instance` the one the calling process works in; returns the one it was in."
  @spec put(atom()) :: atom() | nil
  def put(instance) when is_atom(instance), do: Process.put(@key, instance)

  @doc "The names of instance `instance`'s parts (the current one's by default)."
  @spec names(atom()) :: Names.t()
  def names(instance \\ current()) do
    :persistent_term.get({__MODULE__, instance})
  rescue
    ArgumentError -> raise ArgumentError, "no Dolphin instance #{inspect(instance)} is running"
  end

  @doc "Whether instance `instance` is running."
  @spec running?(atom()) :: boolean()
  def running?(instance), do: Process.whereis(supervisor_name(instance)) != nil

  @impl true
  def init(opts) do
    name = Keyword.fetch!(opts, :name)
    cluster? = Keyword.get(opts, :cluster, false)
    put(name)
    names = struct!(Names, [instance: name, cluster?: cluster?] ++ for({part, module} <- @parts, do: {part, part_name(name, module)}))
    :persistent_term.put({__MODULE__, name}, names)

    children =
      [
        # Vehicles and links by name ({:vehicle, id}, {:link, name}, {:sim, key}).
        {Registry, keys: :unique, name: names.registry},
        {Dolphin.PubSub, name: names.pubsub},
        # The vehicles' views (Dolphin.Vehicles.Views): the table outlives
        # each vehicle's process, and the vehicles restart after it.
        {Dolphin.Vehicles.Views, names},
        # Where vehicles without a process here are reached (Dolphin.Vehicles.Routes):
        # written by the cluster's mirror, read by every command.
        {Dolphin.Vehicles.Routes, name: names.routes},
        # What was set for each vehicle (timeouts): it outlives the vehicles' processes.
        {Dolphin.Vehicles.Settings, name: names.settings},
        # Vehicles before links: a link routes frames to vehicles from its first datagram.
        {DynamicSupervisor, name: names.vehicles, strategy: :one_for_one}
      ] ++
        if(cluster?,
          do: [
            # The mirror of other stations' vehicles, which routes them (so before the fleet).
            Dolphin.Cluster.Mirror
          ],
          else: []
        ) ++
        [
          {DynamicSupervisor, name: names.links, strategy: :one_for_one}
        ] ++
        if(Keyword.get(opts, :links, false),
          do: [
            # The configured links, once the tree they live in is up; a bad endpoint
            # in the configuration stops the start with the reason.
            %{id: :configured_links, start: {Dolphin.Link, :start_configured, []}, restart: :transient}
          ],
          else: []
        ) ++
        [
          # Who is available, picked, busy.
          {Dolphin.Fleet, name: names.fleet, claims: cluster?},
          # The live separation monitor of the missions flown here (Dolphin.Separation).
          {Dolphin.Separation, name: names.separation},
          # Simulated vehicles (Dolphin.Sim) and ArduPilot SITL instances
          # (Dolphin.SITL): empty until asked for; they speak to links over UDP.
          {Dolphin.Sim.Supervisor, name: names.sims},
          {DynamicSupervisor, name: names.sitls, strategy: :one_for_one}
        ]

    # rest_for_one: everything after a crashed child depends on it. A crashed
    # registry takes down (and restarts) the processes registered in it rather
    # than leaving them running nameless; a crashed link supervisor leaves the
    # vehicles alone.
    Supervisor.init(children, strategy: :rest_for_one)
  end

  defp supervisor_name(@default), do: Dolphin.Supervisor.Instance
  defp supervisor_name(name), do: Module.concat(name, Instance)

  defp part_name(@default, module), do: module
  defp part_name(name, module), do: Module.concat(name, module)

  # The instance of the process that started this one: a Task's callers,
  # then a supervised process's ancestors; the default if none says.
  defp inherited do
    Enum.find_value(Process.get(:"$callers", []) ++ Process.get(:"$ancestors", []), @default, &instance_of/1)
  end

  defp instance_of(name) when is_atom(name), do: name |> Process.whereis() |> instance_of()
  defp instance_of(nil), do: nil

  defp instance_of(pid) when is_pid(pid) and node(pid) == node() do
    case Process.info(pid, :dictionary) do
      {:dictionary, dict} -> List.keyfind(dict, @key, 0) |> then(&(&1 && elem(&1, 1)))
      nil -> nil
    end
  end

  defp instance_of(_remote), do: nil
end
