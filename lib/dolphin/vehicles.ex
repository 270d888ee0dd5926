defmodule Dolphin.Vehicles do
  @moduledoc """
  The vehicles the ground station knows, one process each.

  A vehicle is discovered from its first HEARTBEAT (from any component but a
  ground station's) and gets a process under `Dolphin.Vehicles.Supervisor`,
  registered by system id. Links hand every frame to `route/2`, which casts it
  to that process and never waits.

      Dolphin.Vehicles.subscribe(:all)      # {:dolphin, :vehicles, {:vehicle_discovered, 1}}, ...
      Dolphin.Vehicles.list()               # [1, 2, 3]
      Dolphin.Vehicles.state(1)             # {:ok, %Dolphin.Vehicles.State{mode: :guided, battery: 0.87, ...}}
      Dolphin.Vehicles.subscribe(1)         # {:dolphin, {:vehicle, 1}, {:state, 1, [battery: 0.86]}}, ...
      Dolphin.Vehicles.send_message(1, %Dolphin.MAVLink.Ardupilotmega.CommandLong{...})

  Events: `{:vehicle_discovered, sysid}`, `{:vehicle_lost, sysid}` (silent for
  longer than its timeout: 20 s of `Dolphin.Clock` time by default, set with
  `set_timeout/2` or `config :dolphin, vehicle_timeout_ms:`),
  `{:vehicle_reconnected, sysid}`, and per vehicle `{:state, sysid, changes}`.
  """

  alias Dolphin.MAVLink.Frame
  alias Dolphin.MAVLink.Ardupilotmega.Heartbeat
  alias Dolphin.PubSub

  # MAV_TYPE_GCS, and MAV_AUTOPILOT_INVALID (what a ground station sends).
  @gcs_type 6
  @no_autopilot 8

  @doc "The system ids of the known vehicles, ascending."
  @spec list() :: [byte()]
  def list do
    Dolphin.Registry
    |> Registry.select([{{{:vehicle, :"$1"}, :_, :_}, [], [:"$1"]}])
    |> Enum.sort()
  end

  @doc "The state of a vehicle, plus `lost: boolean`."
  @spec state(byte()) :: {:ok, Dolphin.Vehicles.State.t()} | {:error, :unknown_vehicle}
  def state(sysid) do
    case whereis(sysid) do
      nil -> {:error, :unknown_vehicle}
      pid -> {:ok, GenServer.call(pid, :state)}
    end
  end

  @doc "Sends a message to a vehicle through the link it was last heard on."
  @spec send_message(byte(), struct()) :: :ok | {:error, :unknown_vehicle}
  def send_message(sysid, message) do
    case whereis(sysid) do
      nil -> {:error, :unknown_vehicle}
      pid -> GenServer.cast(pid, {:send, message})
    end
  end

  @doc "Sets after how much clock time without a frame a vehicle is lost."
  @spec set_timeout(byte(), pos_integer()) :: :ok | {:error, :unknown_vehicle}
  def set_timeout(sysid, ms) when is_integer(ms) and ms > 0 do
    case whereis(sysid) do
      nil -> {:error, :unknown_vehicle}
      pid -> GenServer.call(pid, {:set_timeout, ms})
    end
  end

  @doc "Subscribes the caller to one vehicle's events, or to `:all` fleet events."
  @spec subscribe(byte() | :all) :: :ok
  def subscribe(:all), do: PubSub.subscribe(:vehicles)
  def subscribe(sysid), do: PubSub.subscribe({:vehicle, sysid})

  @doc "The process of a vehicle, or nil."
  @spec whereis(byte()) :: pid() | nil
  def whereis(sysid) do
    case Registry.lookup(Dolphin.Registry, {:vehicle, sysid}) do
      [{pid, _}] -> pid
      [] -> nil
    end
  end

  @doc false
  # Called by links for every frame: cast it to its vehicle, discovering the
  # vehicle on its first HEARTBEAT from a vehicle component.
  @spec route(Frame.t(), term()) :: :ok
  def route(%Frame{sysid: sysid} = frame, link) do
    case whereis(sysid) do
      nil -> discover(frame, link)
      pid -> GenServer.cast(pid, {:frame, frame, link})
    end
  end

  defp discover(%Frame{message: %Heartbeat{type: type, autopilot: autopilot}} = frame, link)
       when type != @gcs_type and autopilot != @no_autopilot do
    case DynamicSupervisor.start_child(Dolphin.Vehicles.Supervisor, {Dolphin.Vehicles.Vehicle, {frame.sysid, link, []}}) do
      {:ok, pid} ->
        PubSub.publish(:vehicles, {:vehicle_discovered, frame.sysid})
        GenServer.cast(pid, {:frame, frame, link})

      {:error, {:already_started, pid}} ->
        GenServer.cast(pid, {:frame, frame, link})
    end
  end

  defp discover(_frame, _link), do: :ok
end
