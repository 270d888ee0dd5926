# Dolphin's own work per telemetry frame, apart from the runtime's cost of
# moving it: the link's handling of a datagram (decoding it, alone and with
# the routing of its frame to the vehicle's process), and the vehicle's
# fold of the frame (path bookkeeping, duplicate check, state, change
# detection, the view written and published when it changed), each run in a
# loop in this one process — no socket, no message, no process woken.
#
# The frames are a simulated copter's steady telemetry, as a ground station
# asks for it (captured here from the simulator over UDP on 127.0.0.1 for
# 8 s): each is fed again and again with a new sequence number and the
# autopilot's clock moving on. `at rest`: as captured (a copter on its pad:
# its state does not change, no view is published — what `bench/intake.exs`
# measures); `moving`: every position a little further (a view published for
# each GLOBAL_POSITION_INT, a third of the frames).
#
# Compare with `bench/intake.exs`, the whole path in CPU a frame: what is
# not here is the runtime's and the kernel's (a datagram received, the link
# woken, the vehicle's process woken, schedulers put to sleep and woken).
#
#   MIX_ENV=prod mix run bench/frame_work.exs      (FRAMES=200000 for a longer run)

alias Dolphin.Link
alias Dolphin.MAVLink.{Frame, Parser}
alias Dolphin.MAVLink.Ardupilotmega.GlobalPositionInt
alias Dolphin.Vehicles.Vehicle

frames_n = String.to_integer(System.get_env("FRAMES", "100000"))

defmodule Bench.FrameWork do
  # The frames routed to the vehicle, as the link routed them, until `until` (monotonic ms).
  def capture(acc, until) do
    receive do
      {:captured, frame, via} -> capture([{frame, via} | acc], until)
    after
      max(until - System.monotonic_time(:millisecond), 0) -> Enum.reverse(acc)
    end
  end

  # Frame `i` of the loop: a new sequence number, the autopilot's clock on;
  # moving: its position `i` × 1e-7° further north.
  def fresh(%Frame{message: m} = f, i, moving?) do
    m = if Map.has_key?(m, :time_boot_ms), do: %{m | time_boot_ms: 1_000_000 + i * 10}, else: m
    m = if moving? and is_struct(m, GlobalPositionInt), do: %{m | lat: m.lat + i}, else: m
    %{f | seq: rem(i, 256), message: m}
  end

  # µs a frame of the vehicle's fold, from its state `s0`, over `n` frames.
  def fold(s0, steady, n, moving?) do
    frames = List.to_tuple(steady)
    count = tuple_size(frames)

    {us, _} =
      :timer.tc(fn ->
        Enum.reduce(1..n, s0, fn i, s ->
          {f, via} = elem(frames, rem(i, count))
          {:noreply, s} = Vehicle.handle_cast({:frame, fresh(f, i, moving?), via}, s)
          # (Its timers and its sends to itself come to this process.)
          if rem(i, 1_000) == 0, do: flush()
          s
        end)
      end)

    flush()
    us / n
  end

  # µs a frame of the link's decoding: a parser fed one datagram, then finished.
  def decode(datagrams, n) do
    parser = Parser.new()
    rounds = max(div(n, length(datagrams)), 1)

    {us, _} =
      :timer.tc(fn ->
        for _ <- 1..rounds, d <- datagrams do
          {frames, p} = Parser.feed(parser, d)
          {last, _} = Parser.finish(p)
          frames ++ last
        end
      end)

    us / (rounds * length(datagrams))
  end

  # µs a datagram of the link's handling of it (decoded, routed, cast to the
  # vehicle's process, which is suspended: what it is sent waits in its
  # mailbox), from the link's state `l0`, over `n` datagrams from the
  # vehicle's address.
  def link(l0, datagrams, {ip, port}, n) do
    datagrams = List.to_tuple(datagrams)
    count = tuple_size(datagrams)

    {us, _} =
      :timer.tc(fn ->
        Enum.reduce(1..n, l0, fn i, l ->
          {:noreply, l} = Dolphin.Link.Connection.handle_info({:udp, l.socket, ip, port, elem(datagrams, rem(i, count))}, l)
          l
        end)
      end)

    us / n
  end

  def flush do
    receive do
      _ -> flush()
    after
      0 -> :ok
    end
  end
end

me = self()
# A port free a moment ago.
{:ok, probe} = :gen_udp.open(0, ip: {127, 0, 0, 1})
{:ok, port} = :inet.port(probe)
:gen_udp.close(probe)
# The frames are captured until the flag is set; routed as usual always.
capturing = :atomics.new(1, [])
:atomics.put(capturing, 1, 1)

router = fn frame, via ->
  if :atomics.get(capturing, 1) == 1, do: send(me, {:captured, frame, via})
  Dolphin.Vehicles.route(frame, via)
end

{:ok, link} = Link.connect("udpin:127.0.0.1:#{port}", name: "bench_frames", router: router)
{:ok, [1]} = Dolphin.Sim.start(gcs: port, sysids: [1], speedup: 1)
captured = Bench.FrameWork.capture([], System.monotonic_time(:millisecond) + 8_000)
:atomics.put(capturing, 1, 0)
Dolphin.Sim.stop(:all)

[{pid, _}] = Registry.lookup(Dolphin.Instance.names().registry, {:vehicle, 1})
s0 = :sys.get_state(pid)
:ok = :sys.suspend(pid)
# The steady telemetry: what came after the first 2 s (the requests answered).
steady = Enum.drop(captured, div(length(captured), 4))
kinds = steady |> Enum.frequencies_by(fn {f, _} -> f.message.__struct__ |> Module.split() |> List.last() end) |> Enum.sort_by(&(-elem(&1, 1)))
datagrams = Enum.map(steady, fn {f, _} -> Frame.encode(f.message, sysid: f.sysid, compid: f.compid, seq: f.seq) end)
l0 = :sys.get_state(link)
:ok = :sys.suspend(link)

IO.puts("Dolphin's own work a telemetry frame, in one process (#{System.schedulers_online()} schedulers, OTP #{System.otp_release()}, Elixir #{System.version()})")
IO.puts("  #{length(steady)} frames of a simulated copter's steady telemetry, fed #{frames_n} times each way: #{Enum.map_join(kinds, ", ", fn {k, n} -> "#{k} #{n}" end)}")

# Warm-up, then the figures.
_ = Bench.FrameWork.fold(s0, steady, 10_000, true)
_ = Bench.FrameWork.decode(datagrams, 10_000)
decode = Bench.FrameWork.decode(datagrams, frames_n)
rest = Bench.FrameWork.fold(s0, steady, frames_n, false)
moving = Bench.FrameWork.fold(s0, steady, frames_n, true)
{_link, from} = steady |> hd() |> elem(1)
_ = Bench.FrameWork.link(l0, datagrams, from, 10_000)
link_us = Bench.FrameWork.link(l0, datagrams, from, frames_n)
IO.puts("  the link's decoding of a datagram:            #{:erlang.float_to_binary(decode, decimals: 2)} µs a frame")
IO.puts("  the link's handling of it (decoded, routed):  #{:erlang.float_to_binary(link_us, decimals: 2)} µs a frame")
IO.puts("  the vehicle's fold, at rest (no view):        #{:erlang.float_to_binary(rest, decimals: 2)} µs a frame")
IO.puts("  the vehicle's fold, moving (views published): #{:erlang.float_to_binary(moving, decimals: 2)} µs a frame")
IO.puts("  in all: #{:erlang.float_to_binary(link_us + rest, decimals: 1)} µs a frame at rest, #{:erlang.float_to_binary(link_us + moving, decimals: 1)} moving")

:ok = :sys.resume(link)
Link.disconnect(link)
