defmodule Mix.Tasks.Dolphin.SimTest do
  # Starts simulated vehicles and changes the clock speed-up: not async.
  use ExUnit.Case, async: false

  alias Dolphin.MAVLink.{Frame, Parser}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Mix.Tasks.Dolphin.Sim, as: Task

  setup do
    on_exit(fn -> Dolphin.Sim.stop(); Dolphin.Clock.set_speedup(1) end)
  end

  test "options are checked and turned into the simulator's" do
    opts = Task.parse!(~w(--count 3 --speedup 5 --home 41.1,-8.6,100 --ekf-ready 2 --battery-failsafe rtl --camera))
    assert opts[:count] == 3 and opts[:speedup] == 5.0 and opts[:camera]
    assert opts[:home] == %{lat: 41.1, lon: -8.6, alt: 100.0}
    assert opts[:ekf_ready_ms] == 2_000 and opts[:battery_failsafe] == :rtl
    assert opts[:gcs] == "udpout:127.0.0.1:14550"

    assert_raise Mix.Error, ~r/bad option --count/, fn -> Task.parse!(~w(--count many)) end
    assert_raise Mix.Error, ~r/bad --home "north"/, fn -> Task.parse!(~w(--home north)) end
    assert_raise Mix.Error, ~r/unexpected argument "extra"/, fn -> Task.parse!(~w(extra)) end
    assert_raise Mix.Error, ~r/bad --battery-failsafe/, fn -> Task.parse!(~w(--battery-failsafe maybe)) end
    assert_raise Mix.Error, ~r/sends to a ground station: give it udpout/, fn -> Task.start!(Task.parse!(~w(--gcs udpin:0.0.0.0:1))) end
  end

  test "runs vehicles that send to the ground station's endpoint, for a bounded time" do
    {:ok, socket} = :gen_udp.open(0, [:binary, active: true, ip: {127, 0, 0, 1}])
    {:ok, port} = :inet.port(socket)
    on_exit(fn -> :gen_udp.close(socket) end)

    Task.run(~w(--count 2 --speedup 20 --quiet --for 3 --gcs udpout:127.0.0.1:#{port}))
    # It returned after its 3 s of vehicle time, with the vehicles stopped.
    assert Dolphin.Sim.vehicles() == []

    heard = collect(MapSet.new())
    assert MapSet.subset?(MapSet.new([1, 2]), heard)
  end

  defp collect(acc) do
    receive do
      {:udp, _, _, _, datagram} ->
        {frames, _} = Parser.feed(Parser.new(), datagram)
        collect(Enum.reduce(frames, acc, fn %Frame{sysid: s, message: m}, acc -> if match?(%M.Heartbeat{}, m), do: MapSet.put(acc, s), else: acc end))
    after
      0 -> acc
    end
  end
end
