# IEx in this project (`iex -S mix dolphin.console`, `iex -S mix`): the
# console helpers of Dolphin.Console — vehicles(), tasks(), run/2, takeoff/2...
# `h Dolphin.Console` lists them.
import_if_available(Dolphin.Console)

# The script language's vehicle readers and values, as in a script:
# battery(1), location(41.1, -8.6, 120), minutes(5) — and `h battery`,
# `h location` show their docs. `h Dolphin.Script` is the language's overview.
# Only the readers of Dolphin.DSL: its `watch/2` would clash with the console's.
import_if_available(Dolphin.DSL,
  only: [battery: 1, position: 1, altitude: 1, relative_altitude: 1, mode: 1, armed?: 1, connected?: 1, mission_progress: 1]
)

import_if_available(Dolphin.DSL.Values)
