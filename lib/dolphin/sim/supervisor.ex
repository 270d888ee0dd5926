defmodule Dolphin.Sim.Supervisor do
  @moduledoc false
  # The simulated vehicles of a Dolphin.Instance, started on demand.
  # one_for_one: vehicles are independent. Each is :transient, so a vehicle
  # killed as a fault (`Dolphin.Sim.crash(id, reboot: true)`) boots again,
  # while one stopped on purpose stays gone.
  use DynamicSupervisor

  def child_spec(opts), do: %{id: __MODULE__, start: {__MODULE__, :start_link, [Keyword.fetch!(opts, :name)]}, type: :supervisor}

  def start_link(name), do: DynamicSupervisor.start_link(__MODULE__, nil, name: name)

  @impl true
  def init(nil), do: DynamicSupervisor.init(strategy: :one_for_one, max_restarts: 100, max_seconds: 5)
end
