defmodule Dolphin.Vehicles.Settings do
  @moduledoc """
  What an operator or a script set for a vehicle that must outlive the
  vehicle's process: its connection timeout (`Dolphin.Vehicles.set_timeout/2`),
  which a restarted process (a crash, a vehicle forgotten and heard again)
  keeps. One public ETS table, read by the vehicle's process as it starts,
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

  @doc "Forgets what was set for vehicle `sysid`: it gets the defaults again."
  @spec clear(non_neg_integer()) :: :ok
  def clear(sysid) do
    :ets.delete(table(), {:timeout, sysid})
    :ok
  end

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
    {:ok, nil}
  end

  defp table, do: Dolphin.Instance.names().settings
end
