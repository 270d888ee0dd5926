defmodule Dolphin do
  @moduledoc """
  Dolphin for the BEAM: one ground station programs a fleet of drones over MAVLink.

  The application's supervision tree, what each process owns and why it
  stands where it does: `docs/architecture.md` (a test checks that it names
  every child of `Dolphin.Supervisor`).

  - `Dolphin.MAVLink` — the codec (pure).
  - `Dolphin.Link` — `connect/2` an endpoint (`udpin:0.0.0.0:14550`, `udpout:...`, `tcp:...`).
  - `Dolphin.Vehicles` — the vehicles heard, their state, events, commands and missions.
  - `Dolphin.Fleet`, `Dolphin.Engine`, `Dolphin.Script` — picking vehicles, running task trees, scripts.
  - `Dolphin.Mission` — missions as data; `Dolphin.Mission.Platform` flies them as tasks.
  - `Dolphin.Sim` — simulated ArduCopters speaking MAVLink over UDP.
  - `Dolphin.Cluster` — several ground stations, one fleet (distributed Erlang; `docs/cluster.md`).
  - `Dolphin.Clock` — the time source with a speed-up factor; `Dolphin.Events` — the events.

  A link decodes and casts each frame to its vehicle's process and never waits
  on it; a vehicle rebuilds its state from telemetry after a crash; a link's
  crash loses no vehicle (vehicles are answered again as soon as they speak);
  the fleet's record of who is picked survives a vehicle's crash.
  """
end
