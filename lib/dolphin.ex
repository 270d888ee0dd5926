defmodule Dolphin do
  @moduledoc """
  Dolphin for the BEAM: one ground station programs a fleet of drones over MAVLink.

  Built so far: the MAVLink codec, `Dolphin.MAVLink` (pure, no processes).
  The link layer, vehicle processes, simulator and task engine described in the
  project's design come next; the supervision tree (`Dolphin.Application`) grows
  with them.
  """
end
