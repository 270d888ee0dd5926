# Interop tests talk to the reference implementation (pymavlink) in the project's
# venv, which scripts/bootstrap creates; `make test` runs them all.
ExUnit.start()
