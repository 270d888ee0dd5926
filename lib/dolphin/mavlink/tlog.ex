defmodule Dolphin.MAVLink.Tlog do
  @moduledoc """
  The `.tlog` telemetry-log format of MAVProxy, QGroundControl and pymavlink's
  `mavutil`: each record is an 8-byte big-endian timestamp (microseconds since
  the Unix epoch) followed by one raw MAVLink frame.

      iex> alias Dolphin.MAVLink.{Frame, Tlog}
      iex> frame = Frame.encode(%Dolphin.MAVLink.Ardupilotmega.Heartbeat{}, sysid: 1)
      iex> log = IO.iodata_to_binary([Tlog.record(1_700_000_000_000_000, frame), Tlog.record(1_700_000_000_500_000, frame)])
      iex> {records, reader} = Tlog.read(Tlog.reader(), log)
      iex> {[], reader} = Tlog.finish(reader)
      iex> {Enum.map(records, &elem(&1, 0)), Tlog.stats(reader).frames}
      {[1700000000000000, 1700000000500000], 2}

  Reading is streaming (`read/2` takes chunks of any size) and forgiving: when a
  record does not hold a valid frame, it resynchronises on the next place where
  a timestamp is followed by a valid frame, counting what it skipped.
  """

  alias Dolphin.MAVLink.{Frame, Parser, Signing}
  alias Dolphin.MAVLink.Parser.Stats

  @doc "One record: the timestamp (µs since the Unix epoch) and the raw frame."
  @spec record(non_neg_integer(), iodata()) :: iodata()
  def record(timestamp_us, frame), do: [<<timestamp_us::big-64>>, frame]

  defstruct dialect: Dolphin.MAVLink.Ardupilotmega, signing: nil, unknown: :drop, buffer: <<>>, stats: %Stats{}

  @type t :: %__MODULE__{
          dialect: module(),
          signing: Signing.t() | nil,
          unknown: :drop | :forward,
          buffer: binary(),
          stats: Stats.t()
        }

  @doc "A reader; options `:dialect`, `:signing` and `:unknown` as for `Dolphin.MAVLink.Parser.new/1`."
  @spec reader(keyword()) :: t()
  def reader(opts \\ []) do
    parser = Parser.new(opts)
    %__MODULE__{dialect: parser.dialect, signing: parser.signing, unknown: parser.unknown}
  end

  @doc "Feeds a chunk; returns `{timestamp_us, frame}` for each complete record, in order."
  @spec read(t(), binary()) :: {[{non_neg_integer(), Frame.t()}], t()}
  def read(%__MODULE__{buffer: buffer, stats: stats} = reader, chunk) do
    reader = %{reader | stats: %{stats | bytes: stats.bytes + byte_size(chunk)}}
    loop(buffer <> chunk, reader, [])
  end

  @doc """
  Ends the log and returns the records still in the buffer: a last record that
  was waiting for what follows it (see below), and any record behind one cut
  off by the end of the log (that one is dropped and counted as `truncated`,
  and the scan goes on).
  """
  @spec finish(t()) :: {[{non_neg_integer(), Frame.t()}], t()}
  def finish(%__MODULE__{buffer: buffer} = reader), do: loop(buffer, %{reader | buffer: <<>>}, [], :first)

  @doc "Counters of what was read and dropped (`Dolphin.MAVLink.Parser.Stats`)."
  @spec stats(t()) :: Stats.t()
  def stats(%__MODULE__{stats: stats}), do: stats

  # A record is a timestamp and a frame of the size its header declares. What
  # the checksum does not cover is taken only when the next record (or the end
  # of the log) starts right after it: the signature block of a signed frame,
  # and a frame whose id the dialect does not know (with `unknown: :forward`;
  # dropped otherwise). `at_end`: false while the log goes on; in finish/1,
  # :first until a cut-off record has been counted as truncated, then true.
  defp loop(buf, reader, acc, at_end \\ false)

  defp loop(<<ts::big-64, rest::binary>> = buf, reader, acc, at_end) do
    unknown = if reader.unknown == :forward, do: :accept, else: :drop

    case Frame.decode(rest, reader.dialect, unknown: unknown) do
      {:ok, %Frame{} = frame, after_frame} when frame.message == nil or frame.signature != nil ->
        case after_frame do
          <<_next_ts::64, magic, _::binary>> when magic in [0xFD, 0xFE] -> accept(ts, frame, after_frame, reader, acc, at_end)
          <<>> when at_end != false -> accept(ts, frame, after_frame, reader, acc, at_end)
          short when byte_size(short) < 9 and at_end == false -> wait(buf, reader, acc)
          _ -> skip(buf, :garbage, reader, acc, at_end)
        end

      {:ok, frame, after_frame} ->
        accept(ts, frame, after_frame, reader, acc, at_end)

      {:more, _} when at_end == false ->
        wait(buf, reader, acc)

      {:more, _} ->
        skip(buf, cut_off(at_end), reader, acc, true)

      {:error, reason, _} ->
        skip(buf, reason, reader, acc, at_end)
    end
  end

  defp loop(buf, reader, acc, false), do: wait(buf, reader, acc)
  defp loop(<<>>, reader, acc, _at_end), do: wait(<<>>, reader, acc)

  defp loop(rest, reader, acc, at_end),
    do: wait(<<>>, %{reader | stats: Stats.drop(reader.stats, cut_off(at_end), byte_size(rest))}, acc)

  defp cut_off(:first), do: :truncated
  defp cut_off(true), do: :garbage

  defp accept(ts, frame, rest, reader, acc, at_end) do
    case Signing.verify_for(reader, frame) do
      {:ok, reader} ->
        loop(rest, %{reader | stats: Stats.count(reader.stats, frame)}, [{ts, frame} | acc], at_end)

      # A bad signature may be a record cut short: look again from the next byte.
      {:error, :bad_signature, reader} ->
        skip(<<ts::big-64, frame.raw::binary, rest::binary>>, :bad_signature, reader, acc, at_end)

      {:error, reason, reader} ->
        loop(rest, %{reader | stats: Stats.drop(reader.stats, reason, 8 + byte_size(frame.raw))}, acc, at_end)
    end
  end

  # Not a record here: move on one byte and try again.
  defp skip(buf, reason, reader, acc, at_end),
    do: loop(binary_part(buf, 1, byte_size(buf) - 1), %{reader | stats: Stats.drop(reader.stats, reason, 1)}, acc, at_end)

  defp wait(buf, reader, acc), do: {Enum.reverse(acc), %{reader | buffer: :binary.copy(buf)}}
end
