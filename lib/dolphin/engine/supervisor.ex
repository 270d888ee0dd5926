defmodule Dolphin.Engine.Supervisor do
  @moduledoc false
  # The engine's processes: the registry of runs and task nodes (for the
  # console and for stopping by id) and the supervisor of runs. one_for_all:
  # runs register in the registry, so they cannot outlive it.
  use Supervisor

  def start_link(opts \\ []), do: Supervisor.start_link(__MODULE__, opts, name: __MODULE__)

  @impl true
  def init(_opts) do
    # Task and run ids, unique for the life of the node (kept across restarts of this supervisor).
    if :persistent_term.get({Dolphin.Engine, :ids}, nil) == nil,
      do: :persistent_term.put({Dolphin.Engine, :ids}, :atomics.new(1, signed: false))

    # The default signal table (scripts make their own), owned by this supervisor.
    Dolphin.Engine.Signals.new(Dolphin.Engine.Signals)
    # The platforms a run's conditions process may stop (Dolphin.Engine.Stops), owned by this supervisor.
    Dolphin.Engine.Stops.new()

    children = [
      {Registry, keys: :unique, name: Dolphin.Engine.Registry},
      # Runs are temporary: a run that crashed reported its failure to its caller.
      {DynamicSupervisor, name: Dolphin.Engine.Runs, strategy: :one_for_one}
    ]

    Supervisor.init(children, strategy: :one_for_all)
  end
end
