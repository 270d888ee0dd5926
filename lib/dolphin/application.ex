defmodule Dolphin.Application do
  @moduledoc false
  # The OTP application; see Dolphin's moduledoc for the tree.
  use Application

  @impl true
  def start(_type, _args) do
    children = [
      # Vehicles and links by name ({:vehicle, sysid}, {:link, name}).
      {Registry, keys: :unique, name: Dolphin.Registry},
      Dolphin.PubSub,
      # The vehicles' views (Dolphin.Vehicles.Views): the table outlives
      # each vehicle's process, and the vehicles restart after it.
      Dolphin.Vehicles.Views,
      # Where vehicles without a process here are reached (Dolphin.Vehicles.Routes):
      # written by the cluster's mirror, read by every command.
      Dolphin.Vehicles.Routes,
      # What was set for each vehicle (timeouts): it outlives the vehicles' processes.
      Dolphin.Vehicles.Settings,
      # Vehicles before links: a link routes frames to vehicles from its first datagram.
      {DynamicSupervisor, name: Dolphin.Vehicles.Supervisor, strategy: :one_for_one},
      # Several ground stations (Dolphin.Cluster): the :pg scope of their
      # groups, and the mirror of other stations' vehicles, which routes
      # them (so before the fleet).
      %{id: :cluster_scope, start: {:pg, :start_link, [Dolphin.Cluster.Scope]}},
      Dolphin.Cluster.Mirror,
      # The frames each .tlog recorded lately (links sharing a file record a frame once).
      Dolphin.Link.Recorded,
      {DynamicSupervisor, name: Dolphin.Link.Supervisor, strategy: :one_for_one},
      # The configured links, once the tree they live in is up; a bad endpoint
      # in the configuration stops the start with the reason.
      %{id: :configured_links, start: {Dolphin.Link, :start_configured, []}, restart: :transient},
      # The holders of this node's cluster-wide claims on vehicles (Dolphin.Fleet.Claims).
      {Task.Supervisor, name: Dolphin.Fleet.ClaimHolders},
      # Who is available, picked, busy; then the runs of task trees, which use it.
      Dolphin.Fleet,
      Dolphin.Engine.Supervisor,
      # Vehicles whose mission went to another (reassign), held when heard again.
      {Task.Supervisor, name: Dolphin.Mission.Guards},
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
      Dolphin.Cluster.Station,
      # Simulated vehicles (Dolphin.Sim) and ArduPilot SITL instances
      # (Dolphin.SITL): empty until asked for; they speak to links over UDP.
      Dolphin.Sim.Supervisor,
      {DynamicSupervisor, name: Dolphin.SITL.Supervisor, strategy: :one_for_one}
    ]

    # rest_for_one: everything after a crashed child depends on it. A crashed
    # registry takes down (and restarts) the processes registered in it rather
    # than leaving them running nameless; a crashed link supervisor leaves the
    # vehicles alone.
    Supervisor.start_link(children, strategy: :rest_for_one, name: Dolphin.Supervisor)
  end
end
