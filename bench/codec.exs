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
#
# Beside ours, in the same run: the MAVLink C library on the same file
# (bench/peers/mavlink_c.c, built with headers the pinned pymavlink's mavgen
# generates from the same dialect XML, in _build/bench_peers; needs gcc and
# the project's virtualenv, which scripts/bootstrap makes), run before and
# after ours, its best rounds kept; the ratios printed are its time per frame
# over ours (above 1: ours is faster).
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
    peer = CPeer.build()
    c_before = CPeer.run(peer, path, rounds)
    decode = best(rounds, heaps, fn -> decode_all(bytes, chunk) end)
    {_, _, {n, stats}} = decode[:link]

    if stats.bytes_skipped != 0 or n != stats.frames,
      do: Mix.raise("decode dropped data: #{inspect(stats)}")

    {frames, _parser} = Parser.feed(Parser.new(), bytes)
    encode = best(rounds, heaps, fn -> encode_all(frames, 0) end)
    {_, _, size} = encode[:link]

    if size != byte_size(bytes) or IO.iodata_to_binary(Enum.map(frames, &encode/1)) != bytes,
      do: Mix.raise("re-encoded bytes differ from #{path}")

    c = CPeer.best(c_before, CPeer.run(peer, path, rounds))
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
    #{CPeer.describe(c, n, decode[:link], encode[:link])}
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

defmodule CPeer do
  @moduledoc false
  # The MAVLink C library's figures on the same file: bench/peers/mavlink_c.c.

  @dir Path.expand("../_build/bench_peers", __DIR__)
  @python Path.expand("../.venv/bin/python", __DIR__)
  @dialect Path.expand("../priv/mavlink/ardupilotmega.xml", __DIR__)

  # The program, built once per source change: {:ok, path} or {:error, why}.
  def build do
    binary = Path.join(@dir, "mavlink_c")
    sources = [Path.expand("peers/mavlink_c.c", __DIR__), Path.expand("peers/make_c_switch.py", __DIR__), @dialect]

    cond do
      System.find_executable("gcc") == nil -> {:error, "no gcc"}
      not File.exists?(@python) -> {:error, "no virtualenv at #{@python} (scripts/bootstrap makes it)"}
      File.exists?(binary) and Enum.all?(sources, &(mtime(&1) <= mtime(binary))) -> {:ok, binary}
      true -> generate_and_compile(binary)
    end
  end

  defp mtime(path), do: File.stat!(path, time: :posix).mtime

  defp generate_and_compile(binary) do
    include = Path.join(@dir, "include")
    File.rm_rf!(include)
    File.mkdir_p!(include)

    with :ok <- cmd(@python, [Path.join(Path.dirname(@python), "mavgen.py"), "--lang=C", "--wire-protocol=2.0", "-o", include, @dialect]),
         :ok <- cmd(@python, [Path.expand("peers/make_c_switch.py", __DIR__), @dialect, Path.join(include, "peer_switch.h")]),
         :ok <- cmd("gcc", ["-O2", "-w", "-I", include, "-o", binary, Path.expand("peers/mavlink_c.c", __DIR__)]) do
      {:ok, binary}
    end
  end

  defp cmd(program, args) do
    case System.cmd(program, args, stderr_to_stdout: true) do
      {_, 0} -> :ok
      {out, status} -> {:error, "#{Path.basename(program)} exited with #{status}: #{String.slice(out, -500, 500)}"}
    end
  end

  # %{decode_ns:, encode_ns:, ...} of one run of the program, or {:error, why}.
  def run({:ok, binary}, path, rounds) do
    case System.cmd(binary, [path, to_string(rounds)]) do
      {line, 0} ->
        fields = for [k, v] <- Regex.scan(~r/(\w+)=(\S+)/, line, capture: :all_but_first), into: %{}, do: {k, v}

        if fields["identical"] == "yes" and fields["errors"] == "0",
          do: %{decode_ns: String.to_float(fields["decode_ns"]), encode_ns: String.to_float(fields["encode_ns"])},
          else: {:error, "the C library's run did not reproduce the file: #{String.trim(line)}"}

      {out, status} ->
        {:error, "mavlink_c exited with #{status}: #{out}"}
    end
  end

  def run({:error, _} = error, _path, _rounds), do: error

  def best(%{} = a, %{} = b), do: %{decode_ns: min(a.decode_ns, b.decode_ns), encode_ns: min(a.encode_ns, b.encode_ns)}
  def best({:error, _} = error, _), do: error
  def best(_, {:error, _} = error), do: error

  def describe({:error, why}, _n, _decode, _encode), do: "the MAVLink C library: not measured (#{why})"

  def describe(c, n, {decode_us, _, _}, {encode_us, _, _}) do
    ours_decode = decode_us * 1000 / n
    ours_encode = encode_us * 1000 / n

    "the MAVLink C library (mavgen, gcc -O2), same file, wall clock, best rounds: decode #{Float.round(c.decode_ns, 1)} ns/frame, encode #{Float.round(c.encode_ns, 1)} ns/frame\n" <>
      "ours against it (its time over ours, with a link's options): decode #{Float.round(c.decode_ns / ours_decode, 2)}x, encode #{Float.round(c.encode_ns / ours_encode, 2)}x"
  end
end

CodecBench.main()
