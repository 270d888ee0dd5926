import Config

# The dialect compiled into Dolphin.MAVLink.Ardupilotmega lives in priv/mavlink/,
# copied there by scripts/bootstrap from the pinned pymavlink wheel.

import_config "#{config_env()}.exs"
