defmodule Dolphin.MAVLink.Parser.Stats do
  @moduledoc """
  What a `Dolphin.MAVLink.Parser` has seen: `frames` decoded, `unknown_id`
  candidates with a message id the dialect does not define (dropped, or
  returned raw when the parser forwards them), `bytes` fed,
  `bytes_skipped` (dropped: not part of any returned frame), and what was
  dropped by reason: `bad_crc`, `bad_incompat_flags`, `bad_signature`,
  `old_timestamp` (replayed), `unsigned` (refused by the signing policy),
  `truncated` (a frame cut off by the end of the stream: 1 byte is counted
  for it, since the scan goes on inside it).
  """
  defstruct frames: 0,
            bytes: 0,
            bytes_skipped: 0,
            unknown_id: 0,
            bad_crc: 0,
            bad_incompat_flags: 0,
            bad_signature: 0,
            old_timestamp: 0,
            unsigned: 0,
            truncated: 0

  @type t :: %__MODULE__{
          frames: non_neg_integer(),
          bytes: non_neg_integer(),
          bytes_skipped: non_neg_integer(),
          unknown_id: non_neg_integer(),
          bad_crc: non_neg_integer(),
          bad_incompat_flags: non_neg_integer(),
          bad_signature: non_neg_integer(),
          old_timestamp: non_neg_integer(),
          unsigned: non_neg_integer(),
          truncated: non_neg_integer()
        }

  @doc """
  Two counts added (`op` `:add`) or the second taken from the first
  (`:subtract`), field by field.

      iex> alias Dolphin.MAVLink.Parser.Stats
      iex> Stats.combine(%Stats{frames: 3, bytes: 90}, %Stats{frames: 1, bytes: 30, bad_crc: 1}, :add)
      %Stats{frames: 4, bytes: 120, bad_crc: 1}
      iex> Stats.combine(%Stats{frames: 4, bytes: 120}, %Stats{frames: 1, bytes: 30}, :subtract)
      %Stats{frames: 3, bytes: 90}
  """
  # One struct built per call: a link adds its parser's counts for every
  # datagram, where merging the maps key by key cost more than decoding.
  @spec combine(t(), t(), :add | :subtract) :: t()
  def combine(%__MODULE__{} = a, %__MODULE__{} = b, :add) do
    %__MODULE__{
      frames: a.frames + b.frames,
      bytes: a.bytes + b.bytes,
      bytes_skipped: a.bytes_skipped + b.bytes_skipped,
      unknown_id: a.unknown_id + b.unknown_id,
      bad_crc: a.bad_crc + b.bad_crc,
      bad_incompat_flags: a.bad_incompat_flags + b.bad_incompat_flags,
      bad_signature: a.bad_signature + b.bad_signature,
      old_timestamp: a.old_timestamp + b.old_timestamp,
      unsigned: a.unsigned + b.unsigned,
      truncated: a.truncated + b.truncated
    }
  end

  def combine(%__MODULE__{} = a, %__MODULE__{} = b, :subtract) do
    %__MODULE__{
      frames: a.frames - b.frames,
      bytes: a.bytes - b.bytes,
      bytes_skipped: a.bytes_skipped - b.bytes_skipped,
      unknown_id: a.unknown_id - b.unknown_id,
      bad_crc: a.bad_crc - b.bad_crc,
      bad_incompat_flags: a.bad_incompat_flags - b.bad_incompat_flags,
      bad_signature: a.bad_signature - b.bad_signature,
      old_timestamp: a.old_timestamp - b.old_timestamp,
      unsigned: a.unsigned - b.unsigned,
      truncated: a.truncated - b.truncated
    }
  end

  @doc false
  # A frame returned: decoded, or raw with an unknown id.
  @spec count(t(), Dolphin.MAVLink.Frame.t()) :: t()
  def count(stats, %Dolphin.MAVLink.Frame{message: nil}), do: %{stats | unknown_id: stats.unknown_id + 1}
  def count(stats, _frame), do: %{stats | frames: stats.frames + 1}

  @doc false
  # `bytes` dropped for `reason` (garbage is counted in bytes only).
  @spec drop(t(), atom(), non_neg_integer()) :: t()
  def drop(stats, :garbage, bytes), do: %{stats | bytes_skipped: stats.bytes_skipped + bytes}

  def drop(stats, reason, bytes),
    do: %{stats | bytes_skipped: stats.bytes_skipped + bytes} |> Map.update!(reason, &(&1 + 1))
end
