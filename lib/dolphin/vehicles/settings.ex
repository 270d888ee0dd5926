defmodule Dolphin.Vehicles.Settings do
  @moduledoc """
  What an operator or a script set for a vehicle that must outlive the
  vehicle's process: its connection timeout (`Dolphin.Vehicles.set_timeout/2`)
  and the payloads it carries that it cannot announce over MAVLink
  (`Dolphin.Vehicles.put_payloads/2`: a fleet file's, a SITL camera), which
  a restarted process (a crash, a vehicle forgotten and heard again) keeps,
  and which are set before the vehicle is first heard; and the sensor sources
  scripts declared, which every vehicle watches. One public ETS table, read by the vehicle's process as it starts,
  owned by this small process, started before the vehicles' supervisor.
  """

  use GenServer

  @doc false
  # Started by its Dolphin.Instance, which names it.
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, Keyword.fetch!(opts, :name), name: Keyword.fetch!(opts, :name))

  @doc "Keeps `ms` as vehicle `sysid`'s connection timeout."
  @spec put_timeout(non_neg_integer(), pos_integer()) :: :ok
  def put_timeout(sysid, ms) when is_integer(ms) and ms > 0 do
    :ets.insert(table(), {{:timeout, sysid}, ms})
    :ok
  end

  @doc "Forgets the timeout set for vehicle `sysid`: it gets the default again."
  @spec clear(non_neg_integer()) :: :ok
  def clear(sysid) do
    :ets.delete(table(), {:timeout, sysid})
    :ok
  end

  @doc "Keeps `payloads` (sorted, without duplicates) as those vehicle `id` carries besides its components'; `[]` forgets them."
  @spec put_payloads(Dolphin.Vehicles.Id.t(), [atom()]) :: :ok
  def put_payloads(id, []) do
    :ets.delete(table(), {:payloads, id})
    :ok
  end

  def put_payloads(id, payloads) when is_list(payloads) do
    :ets.insert(table(), {{:payloads, id}, payloads |> Enum.uniq() |> Enum.sort()})
    :ok
  end

  @doc "The payloads kept for vehicle `id` (`put_payloads/2`), `[]` when none."
  @spec payloads(Dolphin.Vehicles.Id.t()) :: [atom()]
  def payloads(id) do
    case :ets.lookup(table(), {:payloads, id}) do
      [{_, payloads}] -> payloads
      [] -> []
    end
  end

  @doc """
  Keeps `found`, what vehicle `id`'s fence was before this ground station
  changed it (`Dolphin.Vehicles.Fences`), unless something is kept already:
  the first is what it is given back. `true` when kept now.
  """
  @spec put_found_fence(Dolphin.Vehicles.Id.t(), map()) :: boolean()
  def put_found_fence(id, found), do: :ets.insert_new(table(), {{:found_fence, id}, found})

  @doc "Whether a found fence is kept for vehicle `id`."
  @spec found_fence?(Dolphin.Vehicles.Id.t()) :: boolean()
  def found_fence?(id), do: :ets.member(table(), {:found_fence, id})

  @doc "Takes (and forgets) what `put_found_fence/2` kept for vehicle `id`."
  @spec take_found_fence(Dolphin.Vehicles.Id.t()) :: {:ok, map()} | :none
  def take_found_fence(id) do
    case :ets.take(table(), {:found_fence, id}) do
      [{_, found}] -> {:ok, found}
      [] -> :none
    end
  end

  @doc """
  Adds the declarations of `sensors` (`Dolphin.Sensors.Sensor`s) to the
  sources every vehicle of the instance watches, and returns what they are
  now (`Dolphin.Sensors.Readings.declare/2`). Serialised by this process:
  two runs declaring at once both count.
  """
  @spec declare_sensors([Dolphin.Sensors.Sensor.t()]) :: %{Dolphin.Sensors.Sensor.source() => Dolphin.Sensors.Readings.config()}
  def declare_sensors(sensors), do: GenServer.call(Dolphin.Instance.names().settings, {:declare_sensors, sensors})

  @doc "The sensor sources watched (`declare_sensors/1`), `%{}` when none."
  @spec sensors() :: %{Dolphin.Sensors.Sensor.source() => Dolphin.Sensors.Readings.config()}
  def sensors, do: sensors(table())

  @doc "The connection timeout set for vehicle `sysid`, or `default`."
  @spec timeout(Dolphin.Vehicles.Id.t(), pos_integer() | nil) :: pos_integer() | nil
  def timeout(sysid, default) do
    case :ets.lookup(table(), {:timeout, sysid}) do
      [{_, ms}] -> ms
      [] -> default
    end
  end

  @impl true
  def init(table) do
    :ets.new(table, [:named_table, :public, :set, read_concurrency: true])
    {:ok, table}
  end

  @impl true
  def handle_call({:declare_sensors, sensors}, _from, table) do
    config = Dolphin.Sensors.Readings.declare(sensors(table), sensors)
    :ets.insert(table, {:sensors, config})
    {:reply, config, table}
  end

  defp sensors(table) do
    case :ets.lookup(table, :sensors) do
      [{_, config}] -> config
      [] -> %{}
    end
  end

  defp table, do: Dolphin.Instance.names().settings
end
