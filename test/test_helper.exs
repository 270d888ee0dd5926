# Interop tests talk to the reference implementation (pymavlink) in the project's
# venv, which scripts/bootstrap creates; `make test` runs them all.
#
# SITL tests (tagged :sitl) fly ArduCopter's own flight code: they run whenever
# Dolphin.SITL finds a binary (--sitl-bin is not available here: ARDUPILOT_SITL,
# or ../shared/sitl/arducopter beside the project).
sitl_exclude =
  if Dolphin.SITL.available?() do
    []
  else
    IO.puts("SITL tests skipped: no ArduCopter SITL binary (set ARDUPILOT_SITL=/path/to/arducopter to run them)")
    [:sitl]
  end

ExUnit.start(exclude: sitl_exclude)
