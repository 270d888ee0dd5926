defmodule Mix.Tasks.Mavlink.Decode do
  @shortdoc "Decodes MAVLink frames from a raw byte stream or a .tlog into JSON lines"

  @moduledoc """
  Decodes a file of MAVLink bytes and prints one JSON object per decoded frame
  (the record format of `Dolphin.MAVLink.Record`), then a summary on standard
  error: frames, bytes skipped, CRC failures, signature failures, unknown ids.

      mix mavlink.decode capture.bin
      mix mavlink.decode flight.tlog --tlog
      mix mavlink.decode signed.bin --key 9d3487bc...6baa

  `FILE` may be `-` for standard input.

  ## Options

    * `--tlog` — the file is a telemetry log (8-byte timestamp before each frame)
    * `--key HEX` — the 32-byte signing key (64 hex digits): signed frames are
      verified (bad signature or replayed timestamp: dropped and counted), and
      their records carry `signing.secret_key`
    * `--reject-unsigned` — with `--key`, drop unsigned frames too (by default
      they are decoded: a capture may mix signed and unsigned traffic)

  Frames whose message id the dialect does not define are counted, not printed.

  ## Exit status

  As every task's (README.md, "Exit status"): 1 — the file cannot be read;
  2 — bad usage (an unknown option, a bad key, no such file); 141 — piped
  into a reader that stops early (`| head -1`), it ended at once and
  quietly (`Dolphin.CLI.Stdout`).
  """

  use Mix.Task

  alias Dolphin.MAVLink.{Parser, Record, Signing, Tlog}
  alias Dolphin.MAVLink.Parser.Stats

  @switches [tlog: :boolean, key: :string, reject_unsigned: :boolean]

  @impl Mix.Task
  def run(args) do
    Dolphin.CLI.Signals.exit_on_signal("mavlink.decode", "stopped before the end of the input")
    # A closed pipe (`| head`) ends the task at once, quietly.
    Dolphin.CLI.Stdout.watch()

    case OptionParser.parse(args, strict: @switches) do
      {opts, [file], []} ->
        signing = signing!(opts)
        input = open!(file)
        stats = decode(input, :stdio, tlog: opts[:tlog] == true, signing: signing)
        if file != "-", do: File.close(input)
        IO.puts(:stderr, summary(stats))

      {_, _, [{switch, _} | _]} ->
        usage!("mavlink.decode: unknown or malformed option #{switch}")

      _ ->
        usage!("usage: mix mavlink.decode FILE [--tlog] [--key HEX] [--reject-unsigned]")
    end
  end

  defp signing!(opts) do
    case {opts[:key], opts[:reject_unsigned]} do
      {nil, true} -> usage!("mavlink.decode: --reject-unsigned needs --key")
      {nil, _} -> nil
      {hex, reject?} -> new_signing(hex, if(reject?, do: :reject, else: :accept))
    end
  end

  # A recording's timestamps are in the past: the replay window starts at 0,
  # and only the order of each stream's timestamps is checked.
  defp new_signing(hex, unsigned) do
    case Signing.decode_key(hex) do
      {:ok, key} -> Signing.new(key: key, unsigned: unsigned, timestamp: 0)
      :error -> usage!("mavlink.decode: --key must be 64 hex digits (a 32-byte key), got #{inspect(hex)}")
    end
  end

  defp open!("-") do
    # Bytes, not characters: standard input is read without any decoding.
    :ok = :io.setopts(:standard_io, encoding: :latin1)
    :stdio
  end

  defp open!(path) do
    case File.open(path, [:read, :binary, :raw, :read_ahead]) do
      {:ok, io} -> io
      # A file that is not there is bad usage (2); one that is but cannot be read, a failure (1).
      {:error, why} -> Mix.raise("mavlink.decode: cannot read #{path}: #{:file.format_error(why)}", exit_status: if(why == :enoent, do: 2, else: 1))
    end
  end

  # README.md, "Exit status".
  defp usage!(message), do: Mix.raise(message, exit_status: 2)

  @doc """
  Reads `input` (an IO device) to its end, writes one JSON line per decoded
  frame to `output`, and returns the counters. Options: `:tlog`, `:signing`
  (a `Dolphin.MAVLink.Signing` state or nil).
  """
  @spec decode(IO.device(), IO.device(), keyword()) :: Stats.t()
  def decode(input, output, opts) do
    signing = opts[:signing]
    key = signing && signing.key

    {feed, finish, stats} =
      if opts[:tlog] do
        frames = fn {records, r} -> {Enum.map(records, &elem(&1, 1)), r} end
        {&frames.(Tlog.read(&1, &2)), &frames.(Tlog.finish(&1)), &Tlog.stats/1}
      else
        {&Parser.feed/2, &Parser.finish/1, &Parser.stats/1}
      end

    write = fn frames -> IO.binwrite(output, for(f <- frames, f.message != nil, do: [Record.encode(f, key: key), ?\n])) end
    state = if opts[:tlog], do: Tlog.reader(signing: signing), else: Parser.new(signing: signing)

    state =
      input
      |> read_chunks()
      |> Enum.reduce(state, fn chunk, state ->
        {frames, state} = feed.(state, chunk)
        write.(frames)
        state
      end)

    {frames, state} = finish.(state)
    write.(frames)
    stats.(state)
  end

  defp read_chunks(:stdio), do: IO.binstream(:stdio, 65_536)

  defp read_chunks(io) do
    Stream.unfold(io, fn io ->
      case IO.binread(io, 65_536) do
        data when is_binary(data) -> {data, io}
        :eof -> nil
        {:error, why} -> Mix.raise("mavlink.decode: read error: #{inspect(why)}")
      end
    end)
  end

  @doc "The one-line summary printed on standard error."
  @spec summary(Stats.t()) :: String.t()
  def summary(%Stats{} = s) do
    "frames: #{s.frames}, bytes: #{s.bytes}, bytes skipped: #{s.bytes_skipped}, " <>
      "CRC failures: #{s.bad_crc}, signature failures: #{s.bad_signature + s.old_timestamp + s.unsigned}, " <>
      "unknown ids: #{s.unknown_id}, bad incompat flags: #{s.bad_incompat_flags}, truncated: #{s.truncated}"
  end
end
