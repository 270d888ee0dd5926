defmodule Mix.Tasks.Dolphin.SimTest do
  # Starts simulated vehicles and changes the clock speed-up: not async.
  use ExUnit.Case, async: false

  alias Dolphin.MAVLink.{Frame, Parser}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Mix.Tasks.Dolphin.Sim, as: Task

  setup do
    on_exit(fn ->
      Dolphin.Sim.stop()
      Dolphin.Clock.set_speedup(1)
    end)
  end

  test "options are checked and turned into the simulator's" do
    {:ok, opts} = Task.parse(~w(--count 3 --speedup 5 --home 41.1,-8.6,100 --ekf-ready 2 --battery-failsafe rtl --camera))
    assert opts[:count] == 3 and opts[:speedup] == 5.0 and opts[:camera]
    assert opts[:home] == %{lat: 41.1, lon: -8.6, alt: 100.0}
    assert opts[:ekf_ready_ms] == 2_000 and opts[:battery_failsafe] == :rtl
    assert opts[:gcs] == "udpout:127.0.0.1:14550"

    assert message(~w(--count many)) == "--count many: a number of vehicles from 1 to 16256 (254 a network, each with a system id of its own there)"
    assert message(~w(--home north)) =~ "--home north: LAT,LON,ALT"
    assert message(~w(extra)) =~ ~s(unexpected argument "extra")
    assert message(~w(--battery-failsafe maybe)) == "--battery-failsafe maybe: land, none or rtl"
    assert message(~w(--gcs udpin:0.0.0.0:1)) == "--gcs udpin:0.0.0.0:1: udpout:HOST:PORT here, not udpin"
  end

  test "every value is checked for range and meaning: the flag, the value and what is allowed" do
    assert message(~w(--home 200,0,0)) == "--home 200,0,0: the latitude 200 is not within -90..90 (LAT,LON,ALT: degrees, degrees, metres above mean sea level)"
    assert message(~w(--home 40,400,0)) =~ "--home 40,400,0: the longitude 400 is not within -180..180"
    assert message(~w(--home 40,-7,1e6)) =~ "--home 40,-7,1e6: the altitude 1e6 m is not within -1000..10000"
    assert message(~w(--for 0)) == "--for 0: a number of seconds, more than 0"
    assert message(~w(--for -5)) == "--for -5: a number of seconds, more than 0"
    assert message(~w(--speedup 1e9)) == "--speedup 1e9: a number from 0.01 to 1000 (beyond 1000 the simulated vehicles cannot keep up with the clock)"
    assert message(~w(--speedup 0)) =~ "--speedup 0: a number from 0.01 to 1000"
    assert message(~w(--count 0)) =~ "--count 0: a number of vehicles from 1 to 16256 (254 a network"
    assert message(~w(--count 300)) =~ "--count 300: a network holds 254 vehicles at most (system ids 1..254, 255 is the ground station's): --networks spreads more over several"
    assert message(~w(--count 2000 --networks 4)) =~ "--count 2000 over --networks 4: 500 vehicles a network, system ids 1..500, do not fit in 1..254"
    assert message(~w(--count 3 --networks 4)) == "--networks 4 for --count 3: each network needs a vehicle at least"
    assert message(~w(--networks 65)) == "--networks 65: a number of networks from 1 to 64"
    assert message(~w(--count 16 --networks 8 --gcs udpout:127.0.0.1:65530)) == "--networks 8 with --gcs udpout:127.0.0.1:65530: the networks send to ports 65530..65537, beyond 65535"
    assert message(~w(--first-sysid 255)) == "--first-sysid 255: a system id from 1 to 254 (255 is the ground station's)"
    assert message(~w(--count 10 --first-sysid 250)) == "--count 10 with --first-sysid 250: system ids 250..259 do not fit in 1..254 (255 is the ground station's)"
    assert message(~w(--ekf-ready -1)) == "--ekf-ready -1: a number of seconds, 0 or more"
    assert message(~w(--seed 1.5)) == "--seed 1.5: a whole number"
    assert message(~w(--gcs udpout:127.0.0.1:0)) == "--gcs udpout:127.0.0.1:0: the port is 1..65535"
    assert message(~w(--gcs udpout:127.0.0.1:70000)) == "--gcs udpout:127.0.0.1:70000: the port 70000 is not within 1..65535"

    # The limits themselves are allowed.
    assert {:ok, opts} = Task.parse(~w(--home -90,180,-1000 --speedup 1000 --count 4 --first-sysid 251 --for 0.5))
    assert opts[:home] == %{lat: -90.0, lon: 180.0, alt: -1000.0} and opts[:speedup] == 1000.0
  end

  test "a bad value is bad usage: exit status 2, with the message" do
    error = assert_raise Mix.Error, fn -> Task.run(~w(--home 250,400,0)) end
    assert error.mix == 2
    assert error.message =~ "mix dolphin.sim: --home 250,400,0: the latitude 250 is not within -90..90"
    assert Dolphin.Sim.vehicles() == []
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

  test "a fleet over networks, as a user runs it: system ids repeat on each, a port per network, the frames sent counted" do
    sockets = consecutive_ports(3)
    {:ok, base} = :inet.port(hd(sockets))
    on_exit(fn -> Enum.each(sockets, &:gen_udp.close/1) end)

    result = Dolphin.Test.Shell.run("mix dolphin.sim --count 7 --networks 3 --speedup 20 --for 3 --gcs udpout:127.0.0.1:#{base}")
    assert result.statuses == [0], result.err
    assert result.out =~ "simulating 7 vehicle(s) over 3 networks, system ids 1..2 or 1..3 on each, sending to 127.0.0.1:#{base}..#{base + 2}, a port per network"
    assert [_, sent] = Regex.run(~r/the 7 vehicle\(s\) sent (\d+) frames/, result.out)
    assert String.to_integer(sent) > 0

    # Network 1 has 3 vehicles (1..3), networks 2 and 3 two each (1..2), each from an address of its own.
    heard = for {socket, n} <- Enum.zip(sockets, [3, 2, 2]), do: {heartbeats(socket), n}
    for {senders, n} <- heard, do: assert(senders |> Enum.map(&elem(&1, 0)) |> Enum.uniq() |> Enum.sort() == Enum.to_list(1..n))
  end

  # `n` UDP sockets on consecutive ports of 127.0.0.1 (passive: read after the run).
  defp consecutive_ports(n) do
    {:ok, first} = :gen_udp.open(0, [:binary, active: false, ip: {127, 0, 0, 1}, recbuf: 1_048_576])
    {:ok, base} = :inet.port(first)

    rest = for k <- 1..(n - 1), do: :gen_udp.open(base + k, [:binary, active: false, ip: {127, 0, 0, 1}, recbuf: 1_048_576])

    if Enum.all?(rest, &match?({:ok, _}, &1)) do
      [first | Enum.map(rest, &elem(&1, 1))]
    else
      Enum.each([{:ok, first} | rest], fn
        {:ok, s} -> :gen_udp.close(s)
        _ -> :ok
      end)

      consecutive_ports(n)
    end
  end

  # The {sysid, source port} of every HEARTBEAT waiting on `socket`.
  defp heartbeats(socket, acc \\ MapSet.new()) do
    case :gen_udp.recv(socket, 0, 0) do
      {:ok, {_ip, port, datagram}} ->
        {frames, _} = Parser.feed(Parser.new(), datagram)
        heartbeats(socket, Enum.reduce(frames, acc, fn %Frame{sysid: s, message: m}, acc -> if match?(%M.Heartbeat{}, m), do: MapSet.put(acc, {s, port}), else: acc end))

      {:error, :timeout} ->
        acc
    end
  end

  defp message(argv) do
    assert {:error, %Dolphin.CommandLineError{reason: :usage, message: message}} = Task.parse(argv)
    message
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
