defmodule Dolphin.Application do
  @moduledoc false
  # The OTP application; see Dolphin's moduledoc for the tree.
  use Application

  @impl true
  def start(_type, _args) do
    children = [
      # Several ground stations (Dolphin.Cluster): the :pg scope of their
      # groups, before the default instance, whose mirror of other
      # stations' vehicles is in it.
      %{id: :cluster_scope, start: {:pg, :start_link, [Dolphin.Cluster.Scope]}},
      # The holders of this node's cluster-wide claims on vehicles (Dolphin.Fleet.Claims).
      {Task.Supervisor, name: Dolphin.Fleet.ClaimHolders},
      # The frames each .tlog recorded lately (links sharing a file record a
      # frame once): by file, so one table serves every instance.
      Dolphin.Link.Recorded,
      # The default instance (Dolphin.Instance): the vehicles, their views,
      # pub/sub and clock, the links, the fleet, the simulated and SITL
      # vehicles. It is the cluster's, and opens the configured links.
      {Dolphin.Instance, name: Dolphin.Instance.default(), cluster: true, links: true},
      # The runs of task trees, in whichever instance their context names.
      Dolphin.Engine.Supervisor,
      # Vehicles whose mission went to another (reassign), held when heard again.
      {Task.Supervisor, name: Dolphin.Mission.Guards},
      # Released vehicles being given their fence back (Dolphin.Vehicles.Fences).
      {Task.Supervisor, name: Dolphin.Vehicles.FenceReturns},
      # Scripts (Dolphin.Script.Runner), which start runs: after the engine,
      # so that they stop before it, each stopping its runs in order.
      {DynamicSupervisor, name: Dolphin.Script.Supervisor, strategy: :one_for_one},
      # The IEx console's event store and background runs (Dolphin.Console).
      Dolphin.Console.Supervisor,
      # Live views (Dolphin.Web): one server per view, one process per browser.
      {DynamicSupervisor, name: Dolphin.Web.Supervisor, strategy: :one_for_one},
      {Task.Supervisor, name: Dolphin.Web.Connections},
      # This node's station for other nodes' controllers: nothing here
      # depends on it (its crash restarts only itself; controllers
      # subscribe again when it rejoins its group).
      Dolphin.Cluster.Station
    ]

    # rest_for_one: everything after a crashed child depends on it (the
    # engine, scripts and views on the instance's vehicles and fleet).
    Supervisor.start_link(children, strategy: :rest_for_one, name: Dolphin.Supervisor)
  end
end
