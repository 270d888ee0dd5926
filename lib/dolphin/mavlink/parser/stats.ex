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
