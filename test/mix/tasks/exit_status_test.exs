defmodule Mix.Tasks.ExitStatusTest do
  # One convention for every task (README.md, "Exit status"): 0 done, 1 a
  # failure at run time, 2 bad usage, 130 SIGINT, 143 SIGTERM. Each task's
  # bad usage, as an OS process, in a fresh VM (signals: signals_test.exs
  # and dolphin_run_signals_test.exs).
  use ExUnit.Case, async: true

  import Dolphin.Test.MixCommand, only: [run: 1]

  @moduletag :tmp_dir
  @moduletag timeout: 300_000

  @bad_usage [
    {~w(dolphin.run examples/dry_run.exs --bogus), "bad option --bogus"},
    {~w(dolphin.run no_such_script.exs), "no such script: no_such_script.exs"},
    {~w(dolphin.check examples/dry_run.exs --bogus), "bad option --bogus"},
    {~w(dolphin.plan), "no command given"},
    {~w(dolphin.plan list examples/single_vehicle.exs --bogus), "bad option --bogus"},
    {~w(dolphin.plan import no_such.plan), "no such plan file: no_such.plan"},
    {~w(dolphin.plan export no_such.exs Survey out.plan), "no_such.exs"},
    {~w(dolphin.plan download out.plan --connect udpx:1), "--connect udpx:1"},
    {~w(dolphin.sim --bogus), "bad option --bogus"},
    {~w(dolphin.sim extra), "unexpected argument \"extra\""},
    {~w(dolphin.console --bogus), "bad option --bogus"},
    {~w(dolphin.console --sim 1), "starts a console for IEx"},
    {~w(dolphin.station --sim 1), "a station needs a node name"},
    {~w(dolphin.report), "usage: mix dolphin.report"},
    {~w(dolphin.report no_such.tlog), "cannot read the telemetry log: no_such.tlog"},
    {~w(mavlink.decode), "usage: mix mavlink.decode"},
    {~w(mavlink.decode no_such.bin), "cannot read no_such.bin"},
    {~w(mavlink.encode), "usage: mix mavlink.encode"},
    {~w(mavlink.encode no_such.jsonl), "no such file of JSON records: no_such.jsonl"}
  ]

  for {args, message} <- @bad_usage do
    @tag args: args, message: message
    test "mix #{Enum.join(args, " ")}: bad usage, status 2", ctx do
      {output, status} = run(ctx.args)
      assert status == 2, "exit status #{status}, expected 2:\n#{output}"
      assert output =~ ctx.message
    end
  end

  test "mix dolphin.plan with its --connect port in use: a failure at run time (1), not bad usage", %{tmp_dir: dir} do
    {:ok, socket} = :gen_udp.open(0, [:binary, ip: {127, 0, 0, 1}])
    on_exit(fn -> :gen_udp.close(socket) end)
    {:ok, udp} = :inet.port(socket)

    {output, status} = run(["dolphin.plan", "download", Path.join(dir, "out.plan"), "--connect", "udpin:127.0.0.1:#{udp}"])
    assert status == 1, "exit status #{status}, expected 1:\n#{output}"
    assert output =~ "--connect udpin:127.0.0.1:#{udp}:"
    refute output =~ "usage:"
  end
end
