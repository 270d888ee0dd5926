# The runtime's own cost of a datagram, apart from anything Dolphin does
# with it: the floor under bench/intake.exs's CPU per frame.
#
# A Python process (bench/datagram_sender.py) sends RATE datagrams a second
# (default 17,000, what 1,000 vehicles send) of one MAVLink frame each, from
# 100 sockets, to this VM, which only counts them, three ways:
#
#   active   a gen_udp socket in {active, 100}, one message per datagram to
#            its owner (how Dolphin.Link.Connection reads);
#   forward  the same, each datagram then sent on to one of 100 processes
#            by its source port (as a link hands a frame to its vehicle);
#   socket   a `:socket` read with `:nowait` until the socket is empty, then
#            a select message: no message per datagram.
#
# Over 10 s, once the datagrams flow: datagrams counted and this VM's CPU
# per datagram (all its threads).
#
#   MIX_ENV=prod elixir --erl "+sbwt none +sbwtdcpu none +sbwtdio none" -S mix run bench/datagram_floor.exs
#   (RATE=1700 for what 100 vehicles send)

defmodule Bench.DatagramFloor do
  @window_s 10

  def main do
    rate = String.to_integer(System.get_env("RATE", "17000"))
    IO.puts("datagram floor: #{rate} datagrams a second from another OS process; #{System.schedulers_online()} schedulers, OTP #{System.otp_release()}")
    for way <- [:active, :forward, :socket, :active, :forward, :socket], do: measure(way, rate)
  end

  defp measure(way, rate) do
    counter = :counters.new(1, [:write_concurrency])
    {port, stop} = open(way, counter)
    sender = Path.expand("datagram_sender.py", __DIR__)
    os = Port.open({:spawn_executable, System.find_executable("python3")}, [:binary, :exit_status, args: [sender, "#{port}", "#{rate}", "#{@window_s + 3}"]])
    Process.sleep(2_000)
    {n0, cpu0, t0} = {:counters.get(counter, 1), :erlang.statistics(:runtime) |> elem(0), System.monotonic_time(:millisecond)}
    Process.sleep(@window_s * 1_000)
    {n1, cpu1, t1} = {:counters.get(counter, 1), :erlang.statistics(:runtime) |> elem(0), System.monotonic_time(:millisecond)}
    receive do: ({^os, {:exit_status, _}} -> :ok)
    stop.()
    n = n1 - n0
    IO.puts("  #{String.pad_trailing(Atom.to_string(way), 8)} #{round(n * 1000 / (t1 - t0))} datagrams/s, #{Float.round((cpu1 - cpu0) * 1000 / max(n, 1), 2)} µs of CPU a datagram")
  end

  defp open(:socket, counter) do
    {:ok, sock} = :socket.open(:inet, :dgram, :udp)
    :ok = :socket.setopt(sock, {:socket, :rcvbuf}, 4 * 1024 * 1024)
    :ok = :socket.bind(sock, %{family: :inet, addr: {127, 0, 0, 1}, port: 0})
    {:ok, %{port: port}} = :socket.sockname(sock)
    reader = spawn(fn -> select_loop(sock, counter) end)
    {port, fn -> Process.exit(reader, :kill) && :socket.close(sock) end}
  end

  defp open(way, counter) do
    {:ok, sock} = :gen_udp.open(0, [:binary, active: 100, recbuf: 4 * 1024 * 1024, ip: {127, 0, 0, 1}])
    {:ok, port} = :inet.port(sock)
    workers = if way == :forward, do: List.to_tuple(for(_ <- 1..100, do: spawn(fn -> worker(counter) end))), else: nil
    reader = spawn(fn -> active_loop(sock, counter, workers) end)
    :ok = :gen_udp.controlling_process(sock, reader)
    {port, fn -> Process.exit(reader, :kill) && :gen_udp.close(sock) end}
  end

  defp active_loop(sock, counter, workers) do
    receive do
      {:udp, ^sock, _ip, _port, _data} when workers == nil -> :counters.add(counter, 1, 1)
      {:udp, ^sock, _ip, port, data} -> send(elem(workers, rem(port, 100)), {:frame, data})
      {:udp_passive, ^sock} -> :inet.setopts(sock, active: 100)
    end

    active_loop(sock, counter, workers)
  end

  defp worker(counter) do
    receive do
      {:frame, _data} -> :counters.add(counter, 1, 1)
    end

    worker(counter)
  end

  defp select_loop(sock, counter) do
    drain(sock, counter)

    receive do
      {:"$socket", ^sock, :select, _} -> :ok
    end

    select_loop(sock, counter)
  end

  defp drain(sock, counter) do
    case :socket.recvfrom(sock, 0, [], :nowait) do
      {:ok, {_source, _data}} ->
        :counters.add(counter, 1, 1)
        drain(sock, counter)

      _select_or_error ->
        :ok
    end
  end
end

Bench.DatagramFloor.main()
