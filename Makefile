# The two commands a newcomer needs: `make test` and `make run`. Both install what is
# missing first (scripts/bootstrap: Debian packages, the Python venv, the dialect XML,
# the test vectors).
SHELL := /bin/bash
export LANG := C.UTF-8
export LC_ALL := C.UTF-8
export MIX_HOME ?= $(CURDIR)/_build/mix_home

.PHONY: bootstrap test run bench dialyzer clean

bootstrap:
	@scripts/bootstrap

test: bootstrap
	@scripts/test $(ARGS)

run: bootstrap
	@scripts/demo

bench: bootstrap
	MIX_ENV=prod ERL_FLAGS="+S 1:1" mix bench
	MIX_ENV=prod mix run bench/mission_upload.exs
	MIX_ENV=prod VEHICLES=1000 NETWORKS=4 mix run bench/intake.exs
	MIX_ENV=prod VEHICLES=1000 NETWORKS=4 elixir --erl "+sbwt none +sbwtdcpu none +sbwtdio none" -S mix run bench/intake.exs
	MIX_ENV=prod FEED=replay VEHICLES=2000 NETWORKS=8 elixir --erl "+sbwt none +sbwtdcpu none +sbwtdio none" -S mix run bench/intake.exs
	MIX_ENV=prod mix run bench/sim.exs
	MIX_ENV=prod mix run bench/reaction.exs
	MIX_ENV=prod mix run bench/reaction_floor.exs
	MIX_ENV=prod mix run bench/sensor_reaction.exs
	MIX_ENV=prod mix run bench/report.exs
	MIX_ENV=prod mix run bench/live_view.exs
	MIX_ENV=prod mix run bench/cluster.exs
	MIX_ENV=prod BENCH_FEED=replay BENCH_VEHICLES=2000 BENCH_STATIONS=4 mix run bench/cluster.exs
	MIX_ENV=prod mix run bench/separation.exs
	MIX_ENV=prod elixir --erl "+sbwt none +sbwtdcpu none +sbwtdio none" -S mix run bench/datagram_floor.exs
	MIX_ENV=prod mix run bench/frame_work.exs

dialyzer: bootstrap
	scripts/dialyzer

clean:
	rm -rf _build priv/mavlink/*.xml test/vectors bench/data
