defmodule Dolphin.Vehicles.LinkQuality do
  @moduledoc """
  How good one vehicle's link is, measured by a pure state machine the
  vehicle's process drives: round-trip time and loss both ways.

  - **Round trip**: the ground station sends TIMESYNC (`tc1` 0, `ts1` a stamp
    of its own) about once a second of real time; the autopilot answers with
    its own `tc1` and our `ts1` (ArduPilot and PX4 both do). The time to the
    answer is a sample (real ms: a radio's delay does not shrink with the
    clock's speed-up); `rtt_ms` is the median of the latest 8.
  - **Loss towards the ground station** (`loss_in`): the share of the
    vehicle's frames missing from its sequence numbers, since the last
    measurement, smoothed over the last few.
  - **Round-trip loss** (`loss_rt`): the share of the latest 20 TIMESYNCs
    that got no answer within a few round trips; **loss towards the vehicle**
    (`loss_out`) follows from both: `1 - (1 - loss_rt) / (1 - loss_in)`.

  Every figure is `nil` until measured. The retry timers and budgets of the
  command and mission protocols start from them (`Dolphin.Vehicles.Retry`).

      iex> alias Dolphin.Vehicles.LinkQuality
      iex> q = LinkQuality.new() |> LinkQuality.request(1, 1_000) |> LinkQuality.reply(1, 1_040)
      iex> LinkQuality.figures(q).rtt_ms
      40
  """

  @samples 8
  @outcomes 20
  # Before this many TIMESYNCs have had their chance, loss_rt is not judged.
  @min_outcomes 5
  # Frames a loss_in measurement needs.
  @min_frames 10

  defstruct pending: %{}, samples: [], outcomes: [], window: {0, 0}, rtt_ms: nil, loss_in: nil, loss_rt: nil, loss_out: nil

  @type t :: %__MODULE__{}
  @type figures :: %{rtt_ms: non_neg_integer() | nil, loss_in: float() | nil, loss_out: float() | nil, loss_rt: float() | nil}

  @doc "Nothing measured yet."
  @spec new() :: t()
  def new, do: %__MODULE__{}

  @doc "The figures: `rtt_ms`, `loss_in`, `loss_out`, `loss_rt` (fractions 0.0..1.0), nil until measured."
  @spec figures(t()) :: figures()
  def figures(%__MODULE__{} = q), do: %{rtt_ms: q.rtt_ms, loss_in: q.loss_in, loss_out: q.loss_out, loss_rt: q.loss_rt}

  @doc "A TIMESYNC request stamped `ts1` went out at `now` (real ms)."
  @spec request(t(), integer(), integer()) :: t()
  def request(%__MODULE__{} = q, ts1, now), do: %{q | pending: Map.put(q.pending, ts1, now)}

  @doc "A TIMESYNC answer naming `ts1` came at `now` (real ms); an answer to nothing of ours is ignored."
  @spec reply(t(), integer(), integer()) :: t()
  def reply(%__MODULE__{} = q, ts1, now) do
    case Map.pop(q.pending, ts1) do
      {nil, _} ->
        q

      {sent, pending} ->
        samples = Enum.take([now - sent | q.samples], @samples)
        %{q | pending: pending, samples: samples, rtt_ms: median(samples)} |> outcome(true)
    end
  end

  @doc "Counts frames heard: `received` frames, `lost` missing from their sequence."
  @spec frames(t(), non_neg_integer(), non_neg_integer()) :: t()
  def frames(%__MODULE__{window: {r, l}} = q, received, lost), do: %{q | window: {r + received, l + lost}}

  @doc """
  A measurement at `now` (real ms): TIMESYNCs unanswered for `stale_ms` count
  as lost, the frames since the last measurement give a loss_in sample.
  """
  @spec measure(t(), integer(), pos_integer()) :: t()
  def measure(%__MODULE__{} = q, now, stale_ms) do
    {stale, pending} = Enum.split_with(q.pending, fn {_ts1, sent} -> now - sent > stale_ms end)
    q = Enum.reduce(stale, %{q | pending: Map.new(pending)}, fn _, q -> outcome(q, false) end)

    q =
      case q.window do
        {r, l} when r + l >= @min_frames ->
          sample = l / (r + l)
          %{q | loss_in: if(q.loss_in, do: 0.7 * q.loss_in + 0.3 * sample, else: sample), window: {0, 0}}

        _ ->
          q
      end

    %{q | loss_out: loss_out(q.loss_rt, q.loss_in)}
  end

  # The latest answers (true) and losses (false) of TIMESYNCs.
  defp outcome(q, answered?) do
    outcomes = Enum.take([answered? | q.outcomes], @outcomes)
    loss_rt = if length(outcomes) >= @min_outcomes, do: Enum.count(outcomes, &(not &1)) / length(outcomes)
    %{q | outcomes: outcomes, loss_rt: loss_rt, loss_out: loss_out(loss_rt, q.loss_in)}
  end

  defp loss_out(rt, into) when is_number(rt) and is_number(into) and into < 1.0, do: (1 - (1 - rt) / (1 - into)) |> max(0.0) |> min(1.0)
  defp loss_out(_, _), do: nil

  defp median(samples), do: samples |> Enum.sort() |> Enum.at(div(length(samples), 2))
end
