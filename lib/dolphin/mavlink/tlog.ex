defmodule Dolphin.MAVLink.Tlog do
  @moduledoc """
  The `.tlog` telemetry-log format of MAVProxy, QGroundControl and pymavlink's
  `mavutil`: each record is an 8-byte big-endian timestamp (microseconds since
  the Unix epoch) followed by one raw MAVLink frame.

      iex> alias Dolphin.MAVLink.{Frame, Tlog}
      iex> frame = Frame.encode(%Dolphin.MAVLink.Ardupilotmega.Heartbeat{}, sysid: 1)
      iex> log = IO.iodata_to_binary([Tlog.record(1_700_000_000_000_000, frame), Tlog.record(1_700_000_000_500_000, frame)])
      iex> {records, reader} = Tlog.read(Tlog.reader(), log)
      iex> {Enum.map(records, &elem(&1, 0)), Tlog.stats(Tlog.finish(reader)).frames}
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

  defstruct dialect: Dolphin.MAVLink.Ardupilotmega, signing: nil, buffer: <<>>, stats: %Stats{}

  @type t :: %__MODULE__{dialect: module(), signing: Signing.t() | nil, buffer: binary(), stats: Stats.t()}

  @doc "A reader; options `:dialect` and `:signing` as for `Dolphin.MAVLink.Parser.new/1`."
  @spec reader(keyword()) :: t()
  def reader(opts \\ []) do
    parser = Parser.new(opts)
    %__MODULE__{dialect: parser.dialect, signing: parser.signing}
  end

  @doc "Feeds a chunk; returns `{timestamp_us, frame}` for each complete record, in order."
  @spec read(t(), binary()) :: {[{non_neg_integer(), Frame.t()}], t()}
  def read(%__MODULE__{buffer: buffer, stats: stats} = reader, chunk) do
    reader = %{reader | stats: %{stats | bytes: stats.bytes + byte_size(chunk)}}
    loop(buffer <> chunk, reader, [])
  end

  @doc "Ends the log: a record cut off at the end is counted as `truncated`."
  @spec finish(t()) :: t()
  def finish(%__MODULE__{buffer: <<>>} = reader), do: reader

  def finish(%__MODULE__{buffer: rest, stats: stats} = reader) do
    %{reader | buffer: <<>>, stats: %{stats | truncated: stats.truncated + 1, bytes_skipped: stats.bytes_skipped + byte_size(rest)}}
  end

  @doc "Counters of what was read and dropped (`Dolphin.MAVLink.Parser.Stats`)."
  @spec stats(t()) :: Stats.t()
  def stats(%__MODULE__{stats: stats}), do: stats

  defp loop(<<ts::big-64, rest::binary>> = buf, reader, acc) do
    case Frame.decode(rest, reader.dialect) do
      {:ok, frame, after_frame} ->
        case verify(reader, frame) do
          {:ok, reader} ->
            loop(after_frame, %{reader | stats: Stats.count(reader.stats, frame)}, [{ts, frame} | acc])

          {:error, reason, reader} ->
            loop(after_frame, %{reader | stats: Stats.drop(reader.stats, reason, 8 + byte_size(frame.raw))}, acc)
        end

      {:more, _} ->
        {Enum.reverse(acc), %{reader | buffer: :binary.copy(buf)}}

      {:error, reason, _} ->
        # Not a record here: move on one byte and try again.
        loop(binary_part(buf, 1, byte_size(buf) - 1), %{reader | stats: Stats.drop(reader.stats, reason, 1)}, acc)
    end
  end

  defp loop(buf, reader, acc), do: {Enum.reverse(acc), %{reader | buffer: :binary.copy(buf)}}

  defp verify(reader, frame) do
    case Signing.verify(reader.signing, frame) do
      {:ok, signing} -> {:ok, %{reader | signing: signing}}
      {:error, reason, signing} -> {:error, reason, %{reader | signing: signing}}
    end
  end
end
