# Codec throughput on bench/data/telemetry_mix.bin (100,000 MAVLink 2 frames of a
# copter's telemetry: attitude, position, HUD, status, battery, mission; made by
# scripts/make_vectors.py, which scripts/bootstrap runs), the way a link uses the codec:
#   decode: the file fed to a streaming parser in 4 KiB chunks (a TCP read; UDP
#           datagrams are smaller), every frame checked and decoded into structs;
#   encode: every decoded message re-encoded with its header, as a sender does
#           (the options a link passes; each frame handed on and forgotten); a
#           separate, untimed pass checks that the re-encoded bytes are the file's.
#
# Each round runs in a fresh process that holds only its input, as a link
# process does: the file (a reference-counted binary, outside the heap) to
# decode, or the decoded frames to encode, copied in the way a link receives
# the messages it sends and moved to the old generation before the clock
# starts, with the young heap back to its own size. Without that, the 100,000 frames the benchmark keeps (tens of MB of
# heap) would be copied by the garbage collector during the timed run and
# scattered in memory, which no link does and which doubled the encode time.
#
# The rounds run with a link's process options (`Dolphin.Link.Connection.spawn_opt/0`:
# a 256 KiB young heap), and alternately with the default heap (233 words), whose
# figures are printed last: there the frames of each chunk, live until the chunk
# is done, are copied by several collections.
#
# `make bench` runs it on one scheduler (+S 1), so the figures are per core.
# Environment: BENCH_FILE, BENCH_ROUNDS (default 9), BENCH_CHUNK (default 4096).
defmodule CodecBench do
  alias Dolphin.MAVLink.{Frame, Parser}

  def main do
    path = System.get_env("BENCH_FILE", Path.expand("data/telemetry_mix.bin", __DIR__))
    rounds = String.to_integer(System.get_env("BENCH_ROUNDS", "9"))
    chunk = String.to_integer(System.get_env("BENCH_CHUNK", "4096"))

    bytes =
      case File.read(path) do
        {:ok, bytes} -> bytes
        {:error, why} -> Mix.raise("cannot read the benchmark input #{path}: #{:file.format_error(why)} (scripts/bootstrap makes it)")
      end

    heaps = [link: Dolphin.Link.Connection.spawn_opt(), default: []]
    decode = best(rounds, heaps, fn -> decode_all(bytes, chunk) end)
    {_, _, {n, stats}} = decode[:link]

    if stats.bytes_skipped != 0 or n != stats.frames,
      do: Mix.raise("decode dropped data: #{inspect(stats)}")

    {frames, _parser} = Parser.feed(Parser.new(), bytes)
    encode = best(rounds, heaps, fn -> encode_all(frames, 0) end)
    {_, _, size} = encode[:link]

    if size != byte_size(bytes) or IO.iodata_to_binary(Enum.map(frames, &encode/1)) != bytes,
      do: Mix.raise("re-encoded bytes differ from #{path}")

    rate = fn us -> round(n / (max(us, 1) / 1_000_000)) end
    line = fn {us, cpu, _} -> "#{rate.(us)} frames/s wall (#{Float.round(us / n * 1000, 1)} ns/frame), #{rate.(cpu)} frames/s CPU" end

    IO.puts("""
    codec benchmark: #{n} frames, #{byte_size(bytes)} bytes, #{chunk}-byte chunks, best of #{rounds} rounds, \
    #{System.schedulers_online()} scheduler(s) online
    OTP #{System.otp_release()}, Elixir #{System.version()}, #{:erlang.system_info(:system_architecture)}
    in a process with a link's options #{inspect(heaps[:link])}:
    decode: #{line.(decode[:link])}
    encode: #{line.(encode[:link])}
    in a process with the default heap:
    decode: #{line.(decode[:default])}
    encode: #{line.(encode[:default])}
    re-encoded bytes identical to the file: yes
    """)
  end

  # Timed: decodes the file chunk by chunk, keeping only a count.
  defp decode_all(bytes, chunk), do: decode_chunks(bytes, chunk, Parser.new(), 0)

  defp decode_chunks(<<>>, _chunk, parser, n) do
    {frames, parser} = Parser.finish(parser)
    {n + length(frames), Parser.stats(parser)}
  end

  defp decode_chunks(bytes, chunk, parser, n) do
    size = min(chunk, byte_size(bytes))
    <<part::binary-size(size), rest::binary>> = bytes
    {frames, parser} = Parser.feed(parser, part)
    decode_chunks(rest, chunk, parser, n + length(frames))
  end

  # Timed: encodes every frame, keeping only a byte count.
  defp encode_all([], size), do: size
  defp encode_all([f | rest], size), do: encode_all(rest, size + byte_size(encode(f)))

  # The header options a link gives (Dolphin.Link.Connection), and the
  # compatibility flags when a frame has any.
  defp encode(%Frame{message: message, sysid: sysid, compid: compid, seq: seq, compat_flags: 0}),
    do: Frame.encode(message, sysid: sysid, compid: compid, seq: seq)

  defp encode(%Frame{message: message, sysid: sysid, compid: compid, seq: seq, compat_flags: flags}),
    do: Frame.encode(message, sysid: sysid, compid: compid, seq: seq, compat_flags: flags)

  # Best of N rounds: the machine is shared; the best round is the least
  # disturbed. Wall time and the VM's CPU time are both kept: with one scheduler
  # and nothing else running in the VM, CPU time is this work's, and it stays
  # close to the truth when other programs compete for the cores.
  # The process options alternate round by round, so that both see the same
  # disturbances. Returns `%{name => {wall_us, cpu_us, result}}`.
  defp best(rounds, options, fun) do
    runs = for _ <- 1..rounds, {name, opts} <- options, do: {name, round_in_fresh_process(opts, fun)}

    Map.new(options, fn {name, _} ->
      mine = for {^name, run} <- runs, do: run
      {wall, _, result} = Enum.min_by(mine, &elem(&1, 0))
      {_, cpu, _} = Enum.min_by(mine, &elem(&1, 1))
      {name, {wall, cpu, result}}
    end)
  end

  # The closure's captured input is copied into the new process when it is
  # spawned. A full collection and a minor one leave it in the old generation;
  # a second minor one shrinks the young heap from the size the copy needed
  # (megabytes, through which every allocation would then stream) back to the
  # process's own size, as in a link, whose young heap stays in the caches.
  defp round_in_fresh_process(opts, fun) do
    {pid, ref} =
      :erlang.spawn_opt(fn ->
        :erlang.garbage_collect()
        :erlang.garbage_collect(self(), type: :minor)
        :erlang.garbage_collect(self(), type: :minor)
        {cpu0, _} = :erlang.statistics(:runtime)
        {us, result} = :timer.tc(fun)
        {cpu1, _} = :erlang.statistics(:runtime)
        exit({:round, us, (cpu1 - cpu0) * 1000, result})
      end, [:monitor | opts])

    receive do
      {:DOWN, ^ref, :process, ^pid, {:round, us, cpu, result}} -> {us, cpu, result}
      {:DOWN, ^ref, :process, ^pid, reason} -> Mix.raise("benchmark failed: #{Exception.format_exit(reason)}")
    end
  end
end

CodecBench.main()
