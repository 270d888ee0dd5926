defmodule Dolphin.Application do
  @moduledoc false
  # The OTP application. The codec (Dolphin.MAVLink) is pure and needs no process;
  # the supervision tree grows with the link, vehicle and engine layers.
  use Application

  @impl true
  def start(_type, _args) do
    children = []
    Supervisor.start_link(children, strategy: :one_for_one, name: Dolphin.Supervisor)
  end
end
