# IEx in this project (`iex -S mix dolphin.console`, `iex -S mix`): the
# console helpers of Dolphin.Console — vehicles(), tasks(), run/2, takeoff/2...
# `h Dolphin.Console` lists them.
import_if_available(Dolphin.Console)
