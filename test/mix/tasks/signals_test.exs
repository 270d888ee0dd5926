defmodule Mix.Tasks.SignalsTest do
  # The tasks other than `mix dolphin.run` (dolphin_run_signals_test.exs), each
  # in its own OS process, interrupted by SIGINT (Ctrl-C) or SIGTERM: never
  # the BREAK menu, never OTP's shutdown (status 0 and an EXIT trace), but
  # 130 or 143 and a line that says so.
  use ExUnit.Case, async: true

  import Dolphin.Test.MixCommand, only: [start: 1, start: 2, kill: 2, wait_for: 2, wait_exit: 2]

  @moduletag :tmp_dir
  @moduletag timeout: 300_000

  @signals [{"INT", 130, "interrupted (SIGINT, Ctrl-C)"}, {"TERM", 143, "terminated (SIGTERM)"}]

  defp refute_defaults(output) do
    refute output =~ "BREAK"
    refute output =~ "** (EXIT"
    refute output =~ "SIGTERM received - shutting down"
  end

  # A UDP socket on 127.0.0.1 for what a task sends, closed when the test ends.
  defp udp_listener do
    {:ok, socket} = :gen_udp.open(0, [:binary, ip: {127, 0, 0, 1}, active: true])
    on_exit(fn -> :gen_udp.close(socket) end)
    {:ok, port} = :inet.port(socket)
    {socket, port}
  end

  for {signal, status, words} <- @signals do
    @tag signal: signal, status: status, words: words
    test "SIG#{signal} while mix dolphin.check runs: #{status}, never the 0 of a check without errors", ctx do
      script = Path.join(ctx.tmp_dir, "held.exs")
      File.write!(script, "use Dolphin.Script\nrequire Dolphin.Test.Hold\nDolphin.Test.Hold.here(\"compiling the script\")\n")
      port = start(["dolphin.check", script, "--sim", "1"])
      wait_for(port, ~r/compiling the script/)
      kill(port, ctx.signal)
      output = wait_exit(port, ctx.status)

      assert output =~ "mix dolphin.check: #{ctx.words}: the check did not finish"
      refute_defaults(output)
    end

    @tag signal: signal, status: status, words: words
    test "SIG#{signal} stops mix dolphin.sim in order: its vehicles stopped, #{status}", ctx do
      {_socket, udp} = udp_listener()
      port = start(["dolphin.sim", "--count", "1", "--gcs", "udpout:127.0.0.1:#{udp}"])
      # Its vehicle is heard: the simulator runs.
      assert_receive {:udp, _, _, _, _}, 120_000
      wait_for(port, ~r/simulating 1 vehicle/)
      kill(port, ctx.signal)
      output = wait_exit(port, ctx.status)

      assert output =~ "#{ctx.words}: stopping the simulated vehicles"
      refute_defaults(output)
    end

    @tag signal: signal, status: status, words: words
    test "SIG#{signal} stops a mix dolphin.plan transfer: #{status}, saying what did not finish", ctx do
      {_socket, udp} = udp_listener()
      port = start(["dolphin.plan", "download", Path.join(ctx.tmp_dir, "out.plan"), "--connect", "udpout:127.0.0.1:#{udp}", "--timeout", "600"])
      # Its link sends its heartbeat: it is waiting for a vehicle.
      assert_receive {:udp, _, _, _, _}, 120_000
      kill(port, ctx.signal)
      output = wait_exit(port, ctx.status)

      assert output =~ "mix dolphin.plan: #{ctx.words}: the download did not finish"
      refute_defaults(output)
      refute File.exists?(Path.join(ctx.tmp_dir, "out.plan"))
    end
  end

  test "SIGTERM stops mix dolphin.station in order: its vehicles and links stopped, 143" do
    name = "sigstation#{System.unique_integer([:positive])}@127.0.0.1"
    # Distribution and EPMD on 127.0.0.1 only.
    env = [{"ERL_EPMD_ADDRESS", "127.0.0.1"}, {"ELIXIR_ERL_OPTIONS", "-kernel inet_dist_use_interface {127,0,0,1}"}]
    port = start(["dolphin.station", "--name", name, "--sim", "1", "--speedup", "5"], env)
    wait_for(port, ~r/vehicle 1 discovered/)
    kill(port, "TERM")
    output = wait_exit(port, 143)

    assert output =~ "terminated (SIGTERM): the station stops"
    refute_defaults(output)
  end

  # Before any of the project's code runs: mix reads mix.exs, then compiles
  # the project (here into a build directory of its own, so all of it).
  test "SIGTERM while mix compiles the project for a task: 143, saying nothing ran", %{tmp_dir: dir} do
    port = start(["dolphin.check", "examples/codec_tour.exs"], [{"MIX_BUILD_PATH", Path.join(dir, "build")}])
    wait_for(port, ~r/Compiling \d+ files/)
    kill(port, "TERM")
    output = wait_exit(port, 143)

    assert output =~ "mix dolphin.check: terminated (SIGTERM) while mix was starting it: nothing ran"
    refute_defaults(output)
  end

  # OTP's own SIGTERM would end the suite with 0, a pass.
  test "SIGTERM ends mix test with 143, saying the suite did not finish", %{tmp_dir: dir} do
    port = start(["test", "test/dolphin/clock_test.exs"], [{"MIX_BUILD_PATH", Path.join(dir, "build")}])
    wait_for(port, ~r/Compiling \d+ files/)
    kill(port, "TERM")
    output = wait_exit(port, 143)

    assert output =~ "mix test: terminated (SIGTERM): the suite did not finish"
    refute_defaults(output)
  end
end
