# Interop tests talk to the reference implementation (pymavlink) in the project's
# venv, which scripts/bootstrap creates; `make test` runs them all.
#
# :lossy_transfer tests move missions through an impairing proxy
# (test/dolphin/test/udp_proxy_sim_test.exs); they fail on known defects of the
# mission protocol until the lossy mission-transfer work fixes them.
ExUnit.start(exclude: [:lossy_transfer])
IO.puts("Excluded by default: :lossy_transfer (mission transfer over a lossy link, known to fail); run with --include lossy_transfer")
