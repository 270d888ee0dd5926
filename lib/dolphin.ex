defmodule Dolphin do
  @moduledoc """
  Dolphin for the BEAM: one ground station programs a fleet of drones over MAVLink.

  The processes so far:

  ```
  Dolphin.Supervisor (one_for_one)
  ├─ Dolphin.Registry            vehicles {:vehicle, sysid} and links {:link, name}
  ├─ Dolphin.PubSub              Registry with duplicate keys: state changes, fleet events
  ├─ Dolphin.Vehicles.Supervisor one Dolphin.Vehicles.Vehicle per discovered vehicle
  └─ Dolphin.Link.Supervisor     one Dolphin.Link.Connection per endpoint (owns its socket)
  ```

  - `Dolphin.MAVLink` — the codec (pure).
  - `Dolphin.Link` — `connect/2` an endpoint (`udpin:0.0.0.0:14550`, `udpout:...`).
  - `Dolphin.Vehicles` — the vehicles heard, their state, events, sending to them.
  - `Dolphin.Clock` — the time source with a speed-up factor.

  A link decodes and casts each frame to its vehicle's process and never waits
  on it; a vehicle rebuilds its state from telemetry after a crash; a link's
  crash loses no vehicle (vehicles are answered again as soon as they speak).
  """
end
