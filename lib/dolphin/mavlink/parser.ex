defmodule Dolphin.MAVLink.Parser do
  @moduledoc """
  A streaming MAVLink decoder: feed it bytes in chunks of any size (a UDP
  datagram holding several frames, a TCP stream split anywhere) and get back
  the frames completed so far. It is pure data: the process owning a socket
  keeps it.

      iex> alias Dolphin.MAVLink.{Frame, Parser}
      iex> bytes = Frame.encode(%Dolphin.MAVLink.Ardupilotmega.Heartbeat{type: 2}, sysid: 1)
      iex> parser = Parser.new()
      iex> {[], parser} = Parser.feed(parser, "noise" <> binary_part(bytes, 0, 4))
      iex> {[frame], parser} = Parser.feed(parser, binary_part(bytes, 4, byte_size(bytes) - 4))
      iex> {frame.sysid, frame.message.type}
      {1, 2}
      iex> Parser.stats(parser).bytes_skipped
      5

  After bytes that are not a valid frame it resynchronises by scanning for the
  next magic byte, starting one byte after a failed candidate, so that a valid
  frame is found even right after a truncated or corrupted one. Nothing is
  raised; each dropped byte is counted, with the reason, in `stats/1`.

  Options of `new/1`:

    * `:dialect` — the dialect module (default `Dolphin.MAVLink.default_dialect/0`:
      ArduPilot's, with the user's own messages when there are any);
    * `:signing` — a `Dolphin.MAVLink.Signing` state: signed frames are then
      verified (bad signature or replayed timestamp: dropped), unsigned ones
      follow its policy. Without it, frames pass unverified.

    * `:unknown` — `:drop` (default) refuses candidates whose message id the
      dialect does not define, as the MAVLink C library does (their checksum
      cannot be checked); `:forward` returns the well-framed ones with
      `message: nil`, for a router (see `Dolphin.MAVLink.Frame.decode/3`: such
      a frame comes out once the byte after it has arrived). Either way they
      are counted as `unknown_id`.

    * `:batch` — `false` decodes every frame in Elixir, without the C fast
      path of `Dolphin.MAVLink.Native` (the frames are the same).

  The frames returned never depend on how the stream was cut into chunks.
  """

  alias Dolphin.MAVLink.{Frame, Signing}

  alias Dolphin.MAVLink.Native
  alias Dolphin.MAVLink.Parser.Stats

  defstruct dialect: Dolphin.MAVLink.Ardupilotmega,
            decoder: nil,
            batch: nil,
            signing: nil,
            unknown: :drop,
            buffer: <<>>,
            in_sync: true,
            stats: %Stats{}

  @type t :: %__MODULE__{
          dialect: module(),
          decoder: function() | nil,
          batch: Native.table() | nil,
          signing: Signing.t() | nil,
          unknown: :drop | :forward,
          buffer: binary(),
          in_sync: boolean(),
          stats: Stats.t()
        }

  @doc "A parser; see the module doc for options."
  @spec new(keyword()) :: t()
  def new(opts \\ []) do
    dialect = Keyword.get_lazy(opts, :dialect, &Dolphin.MAVLink.default_dialect/0)
    signing = Keyword.get(opts, :signing)

    %__MODULE__{
      dialect: dialect,
      decoder: Frame.decoder(dialect),
      # Signed links verify every frame (unsigned ones by their policy): no fast path.
      batch: if(signing == nil and Keyword.get(opts, :batch, true), do: Native.for_dialect(dialect)),
      signing: signing,
      unknown: unknown!(Keyword.get(opts, :unknown, :drop))
    }
  end

  defp unknown!(mode) when mode in [:drop, :forward], do: mode
  defp unknown!(other), do: raise(ArgumentError, "unknown: must be :drop or :forward, got: #{inspect(other)}")

  @doc "Feeds a chunk of bytes; returns the frames it completed, in order."
  @spec feed(t(), binary()) :: {[Frame.t()], t()}
  def feed(%__MODULE__{buffer: buffer, stats: stats} = parser, chunk) do
    buf = if buffer == <<>>, do: chunk, else: buffer <> chunk
    parser = %{parser | stats: %{stats | bytes: stats.bytes + byte_size(chunk)}}
    loop(buf, 0, parser, [])
  end

  @doc """
  Ends the stream and returns the frames still in the buffer: the last
  unknown-id frame that was waiting for the byte after it, and any frame behind
  a candidate cut off by the end of the stream (that candidate is dropped and
  counted as `truncated`, and the scan goes on inside it).
  """
  @spec finish(t()) :: {[Frame.t()], t()}
  def finish(%__MODULE__{buffer: <<>>} = parser), do: {[], parser}
  def finish(%__MODULE__{buffer: buf} = parser), do: loop(buf, 0, %{parser | buffer: <<>>}, [], 0, 0, :first)

  @doc "Counters of what was decoded and dropped."
  @spec stats(t()) :: Stats.t()
  def stats(%__MODULE__{stats: stats}), do: stats

  # The buffer is walked by offset (`at`): a sub-binary per frame for "the rest"
  # would cost as much as decoding a small message.
  # Good frames are counted in loop arguments and written into the stats once
  # per feed: a struct update per frame costs more than decoding a small message.
  # `at_end` is false while the stream goes on; in finish/1 it is :first until a
  # cut-off candidate has been counted as truncated, then true.
  # The fast path first: every healthy frame from `at` on, in C; whatever it
  # stops at, one step in Elixir, then the fast path again.
  defp loop(buf, at, parser, acc, frames \\ 0, unknown \\ 0, at_end \\ false)

  defp loop(buf, at, %__MODULE__{batch: batch} = parser, acc, frames, unknown, at_end) when batch != nil do
    case Native.decode(buf, at, batch, acc) do
      # All of it (a datagram's frames, mostly): nothing left to look at.
      {acc, next, n} when n > 0 and next == byte_size(buf) -> done(buf, next, %{parser | in_sync: true}, acc, frames + n, unknown)
      {acc, next, n} when n > 0 -> loop(buf, next, %{parser | in_sync: true}, acc, frames + n, unknown, at_end)
      _none -> step(buf, at, parser, acc, frames, unknown, at_end)
    end
  end

  defp loop(buf, at, parser, acc, frames, unknown, at_end), do: step(buf, at, parser, acc, frames, unknown, at_end)

  defp step(buf, at, parser, acc, frames, unknown, at_end) do
    case Frame.decode_at(buf, at, parser.decoder, decode_opts(parser.unknown, parser.in_sync, at_end)) do
      {:ok, %Frame{signature: nil} = frame, next} when parser.signing == nil ->
        loop_ok(buf, next, parser, [frame | acc], frame, frames, unknown, at_end)

      {:ok, frame, next} ->
        case Signing.verify_for(parser, frame) do
          {:ok, parser} ->
            loop_ok(buf, next, parser, [frame | acc], frame, frames, unknown, at_end)

          # A bad signature may be a frame cut short whose "signature" is the
          # start of the next frame, and an unknown-id frame is vouched for by
          # nothing: look again from the byte after the magic.
          {:error, reason, parser} when reason == :bad_signature or frame.message == nil ->
            parser = %{parser | in_sync: false, stats: Stats.drop(parser.stats, reason, 1)}
            loop(buf, at + 1, parser, acc, frames, unknown, at_end)

          # A replayed or refused frame is whole: drop all of it.
          {:error, reason, parser} ->
            parser = %{parser | in_sync: false, stats: Stats.drop(parser.stats, reason, next - at)}
            loop(buf, next, parser, acc, frames, unknown, at_end)
        end

      {:more, at} when at_end == false or at == byte_size(buf) ->
        done(buf, at, parser, acc, frames, unknown)

      # The stream ended inside this candidate: drop its first byte and look on.
      {:more, at} ->
        reason = if at_end == :first, do: :truncated, else: :garbage
        parser = %{parser | in_sync: false, stats: Stats.drop(parser.stats, reason, 1)}
        loop(buf, at + 1, parser, acc, frames, unknown, true)

      {:error, reason, next} ->
        loop(buf, next, %{parser | in_sync: false, stats: Stats.drop(parser.stats, reason, next - at)}, acc, frames, unknown, at_end)
    end
  end

  # The frames found, in order, and the parser with the counts and only the
  # unfinished tail from `at` (not the whole chunk it points into).
  defp done(buf, at, parser, acc, frames, unknown) do
    stats = %{parser.stats | frames: parser.stats.frames + frames, unknown_id: parser.stats.unknown_id + unknown}
    tail = if at == byte_size(buf), do: <<>>, else: :binary.copy(binary_part(buf, at, byte_size(buf) - at))
    {:lists.reverse(acc), %{parser | buffer: tail, stats: stats}}
  end

  # Literal option lists: nothing is built per frame for them.
  defp decode_opts(:drop, _in_sync, _at_end), do: []
  defp decode_opts(:forward, true, false), do: [unknown: :forward, in_sync: true]
  defp decode_opts(:forward, false, false), do: [unknown: :forward, in_sync: false]
  defp decode_opts(:forward, true, _at_end), do: [unknown: :forward, in_sync: true, at_end: true]
  defp decode_opts(:forward, false, _at_end), do: [unknown: :forward, in_sync: false, at_end: true]

  defp loop_ok(buf, next, %__MODULE__{in_sync: true} = parser, acc, %Frame{message: nil}, frames, unknown, at_end),
    do: loop(buf, next, parser, acc, frames, unknown + 1, at_end)

  defp loop_ok(buf, next, %__MODULE__{in_sync: true} = parser, acc, _frame, frames, unknown, at_end),
    do: loop(buf, next, parser, acc, frames + 1, unknown, at_end)

  defp loop_ok(buf, next, parser, acc, frame, frames, unknown, at_end),
    do: loop_ok(buf, next, %{parser | in_sync: true}, acc, frame, frames, unknown, at_end)
end
