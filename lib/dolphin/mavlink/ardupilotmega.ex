defmodule Dolphin.MAVLink.Ardupilotmega do
  @moduledoc """
  The `ardupilotmega` dialect (ArduPilot's; it includes common, standard, minimal,
  uAvionix, icarous, loweheiser, cubepilot and csAirLink): 301 messages, compiled
  from `priv/mavlink/ardupilotmega.xml` at build time.

      iex> alias Dolphin.MAVLink.Ardupilotmega, as: APM
      iex> APM.message_module("HEARTBEAT")
      Dolphin.MAVLink.Ardupilotmega.Heartbeat
      iex> APM.message_info(0)
      {Dolphin.MAVLink.Ardupilotmega.Heartbeat, 50, 9, 9}
      iex> APM.enum_value(:mav_type, :mav_type_quadrotor)
      {:ok, 2}
      iex> APM.enum_name(:mav_cmd, 16)
      {:ok, :mav_cmd_nav_waypoint}
  """

  use Dolphin.MAVLink.Dialect, xml: "../../../priv/mavlink/ardupilotmega.xml"
end
