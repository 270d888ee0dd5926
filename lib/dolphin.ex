defmodule Dolphin do
  @moduledoc """
  Dolphin for the BEAM: one ground station programs a fleet of drones over MAVLink.

  ```
  Dolphin.Supervisor (rest_for_one)
  ├─ Dolphin.Registry            vehicles {:vehicle, sysid}, links {:link, name}, simulated vehicles {:sim, sysid}
  ├─ Dolphin.PubSub              Registry with duplicate keys: state changes, vehicle and engine events
  ├─ Dolphin.Vehicles.Views      owner of the ETS table of every vehicle's latest view (read by anyone)
  ├─ Dolphin.Vehicles.Supervisor one Dolphin.Vehicles.Vehicle per discovered vehicle
  │                              (each runs its command and mission protocols as :gen_statem)
  ├─ Dolphin.Link.Supervisor     one Dolphin.Link.Connection per endpoint (owns its socket)
  ├─ configured links            (connects `config :dolphin, links:` and goes away)
  ├─ Dolphin.Cluster.Scope       the :pg scope of a cluster of ground stations (Dolphin.Cluster)
  ├─ Dolphin.Cluster.Mirror      other stations' vehicles, routed and published here once joined
  ├─ Dolphin.Fleet               who is picked, busy; waiting picks; reservations (no vehicle state)
  ├─ Dolphin.Engine.Supervisor   registry of runs and task nodes; one process tree per run
  │                              (a node per combinator; a Dolphin.Mission.Executor per flying mission)
  ├─ Dolphin.Console.Supervisor  the IEx console's event store and background runs
  ├─ Dolphin.Cluster.Station     this node's vehicles, told to the controllers that joined it
  └─ Dolphin.Sim.Supervisor      simulated vehicles, added when `Dolphin.Sim.start/1` asks for them
  ```

  - `Dolphin.MAVLink` — the codec (pure).
  - `Dolphin.Link` — `connect/2` an endpoint (`udpin:0.0.0.0:14550`, `udpout:...`, `tcp:...`).
  - `Dolphin.Vehicles` — the vehicles heard, their state, events, commands and missions.
  - `Dolphin.Fleet`, `Dolphin.Engine`, `Dolphin.Script` — picking vehicles, running task trees, scripts.
  - `Dolphin.Mission` — missions as data; `Dolphin.Mission.Platform` flies them as tasks.
  - `Dolphin.Sim` — simulated ArduCopters speaking MAVLink over UDP.
  - `Dolphin.Cluster` — several ground stations, one fleet (distributed Erlang; `docs/cluster.md`).
  - `Dolphin.Clock` — the time source with a speed-up factor; `Dolphin.Telemetry` — the events.

  A link decodes and casts each frame to its vehicle's process and never waits
  on it; a vehicle rebuilds its state from telemetry after a crash; a link's
  crash loses no vehicle (vehicles are answered again as soon as they speak);
  the fleet's record of who is picked survives a vehicle's crash.
  """
end
