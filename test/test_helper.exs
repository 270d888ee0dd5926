# Interop tests talk to the reference implementation (pymavlink) in the project's
# venv, which scripts/bootstrap creates; `make test` runs them all.
#
# SITL tests (tagged :sitl) fly ArduCopter's own flight code: they run whenever
# Dolphin.SITL finds a binary (ARDUPILOT_SITL, or ../shared/sitl/arducopter
# beside the project).
sitl_exclude =
  if Dolphin.SITL.available?() do
    []
  else
    IO.puts("SITL tests skipped: no ArduCopter SITL binary (set ARDUPILOT_SITL=/path/to/arducopter to run them)")
    [:sitl]
  end

# The shared test vectors are an extra cross-check: without the shared folder
# (../shared beside the project, or $DOLPHIN_SHARED) their tests are excluded.
shared_exclude =
  if Dolphin.Test.Vectors.available?(:shared) do
    []
  else
    dir = Dolphin.Test.Vectors.dir(:shared)
    IO.puts("shared vectors not found in #{dir}: their cross-check is skipped (set DOLPHIN_SHARED to the shared folder to run it)")
    [:shared_vectors]
  end

# Browser tests (tagged :browser) load pages in a headless Chromium and read
# back what it drew; they run whenever one is installed (scripts/bootstrap
# installs Debian's chromium).
browser_exclude =
  if Dolphin.Test.Browser.available?() do
    []
  else
    IO.puts("browser tests skipped: no chromium (install Debian's chromium, or set CHROMIUM=/path/to/chromium, to run them)")
    [:browser]
  end

# Tests that fly simulated fleets each have a Dolphin.Instance of their own
# and run async, at most twice the cores at once (ExUnit's default; more
# were barely quicker on a loaded machine, see docs/testing.md).
# DOLPHIN_TEST_TIMES=FILE: each module's time written there (Dolphin.Test.Timings).
ExUnit.start(exclude: sitl_exclude ++ shared_exclude ++ browser_exclude)
ExUnit.configure(formatters: Dolphin.Test.Timings.formatters(ExUnit.configuration()[:formatters]))
