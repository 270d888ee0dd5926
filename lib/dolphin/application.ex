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
      # Vehicles before links: a link routes frames to vehicles from its first datagram.
      {DynamicSupervisor, name: Dolphin.Vehicles.Supervisor, strategy: :one_for_one},
      {DynamicSupervisor, name: Dolphin.Link.Supervisor, strategy: :one_for_one},
      # The configured links, once the tree they live in is up; a bad endpoint
      # in the configuration stops the start with the reason.
      %{id: :configured_links, start: {Task, :start_link, [&Dolphin.Link.connect_configured/0]}, restart: :temporary}
    ]

    # one_for_one: a crashed link or vehicle supervisor is restarted alone; the
    # registries outlive them, so a vehicle keeps its name across a link restart.
    Supervisor.start_link(children, strategy: :one_for_one, name: Dolphin.Supervisor)
  end
end
