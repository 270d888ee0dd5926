# Interop tests talk to the reference implementation (pymavlink) in the project's
# venv, which scripts/bootstrap creates; `make test` runs them all.
#
# The shared test vectors are an extra cross-check: without the shared folder
# (../shared beside the project, or $DOLPHIN_SHARED) their tests are excluded.
exclude =
  if Dolphin.Test.Vectors.available?(:shared) do
    []
  else
    dir = Dolphin.Test.Vectors.dir(:shared)
    IO.puts("shared vectors not found in #{dir}: their cross-check is skipped (set DOLPHIN_SHARED to the shared folder to run it)")
    [:shared_vectors]
  end

ExUnit.start(exclude: exclude)
