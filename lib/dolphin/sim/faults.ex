defmodule Dolphin.Sim.Faults do
  @moduledoc """
  A simulated radio link's faults, applied to every datagram a simulated
  vehicle sends or receives (`Dolphin.Sim.set_faults/2`):

  | key | meaning |
  | --- | --- |
  | `loss` | probability that a datagram is dropped |
  | `duplicate` | probability that it arrives twice |
  | `reorder` | probability that it is held back 20–100 ms (clock time) so that later ones overtake it |
  | `corrupt` | probability that one of its bytes is flipped (the receiver's CRC check drops the frame) |
  | `latency` | clock milliseconds every datagram takes |
  | `silence` | `true`: nothing goes through either way (the radio is out of range) |

  Randomness comes from a seeded generator, so a run with the same seed and the
  same traffic draws the same faults.

      iex> faults = Dolphin.Sim.Faults.new(%{loss: 1.0}, 7)
      iex> {deliveries, _} = Dolphin.Sim.Faults.apply(faults, "frame")
      iex> deliveries
      []
  """

  import Bitwise, only: [<<<: 2, bxor: 2]

  @keys [:loss, :duplicate, :reorder, :corrupt, :latency, :silence]
  # A datagram reordered is held back this long (clock ms) on top of the latency.
  @reorder_min_ms 20
  @reorder_max_ms 100

  defstruct loss: 0.0, duplicate: 0.0, reorder: 0.0, corrupt: 0.0, latency: 0, silence: false, rand: nil

  @type t :: %__MODULE__{}

  @doc "Faults from a map or keyword list, with a seed for their randomness."
  @spec new(map() | keyword(), term()) :: t()
  def new(faults, seed) do
    update(%__MODULE__{rand: :rand.seed_s(:exsss, :erlang.phash2(seed, 1 <<< 32))}, faults)
  end

  @doc "Changes some faults (unknown keys and bad values raise `ArgumentError`)."
  @spec update(t(), map() | keyword()) :: t()
  def update(%__MODULE__{} = faults, changes) do
    Enum.reduce(changes, faults, fn
      {key, p}, acc when key in [:loss, :duplicate, :reorder, :corrupt] and is_number(p) and p >= 0 and p <= 1 ->
        Map.put(acc, key, p * 1.0)

      {:latency, ms}, acc when is_integer(ms) and ms >= 0 ->
        %{acc | latency: ms}

      {:silence, flag}, acc when is_boolean(flag) ->
        %{acc | silence: flag}

      {key, value}, _acc ->
        raise ArgumentError,
              "bad fault #{inspect(key)}: #{inspect(value)} (known: #{inspect(@keys)}; probabilities 0..1, latency in ms, silence true/false)"
    end)
  end

  @doc "The faults as a plain map."
  @spec to_map(t()) :: map()
  def to_map(%__MODULE__{} = f), do: Map.take(f, @keys)

  @doc """
  What happens to one datagram: a list of `{delay_ms, bytes}` deliveries (none
  when it is lost), and the new state.
  """
  @spec apply(t(), binary()) :: {[{non_neg_integer(), binary()}], t()}
  def apply(%__MODULE__{silence: true} = f, _datagram), do: {[], f}

  def apply(%__MODULE__{loss: 0.0, duplicate: 0.0, reorder: 0.0, corrupt: 0.0, latency: latency} = f, datagram),
    do: {[{latency, datagram}], f}

  def apply(%__MODULE__{} = f, datagram) do
    {lost, r} = :rand.uniform_s(f.rand)

    if lost < f.loss do
      {[], %{f | rand: r}}
    else
      {corrupt, r} = :rand.uniform_s(r)
      {datagram, r} = if corrupt < f.corrupt, do: flip(datagram, r), else: {datagram, r}
      {late, r} = :rand.uniform_s(r)
      {extra, r} = :rand.uniform_s(r)
      delay = if late < f.reorder, do: f.latency + @reorder_min_ms + round(extra * (@reorder_max_ms - @reorder_min_ms)), else: f.latency
      {twice, r} = :rand.uniform_s(r)
      copies = if twice < f.duplicate, do: [{delay, datagram}, {delay, datagram}], else: [{delay, datagram}]
      {copies, %{f | rand: r}}
    end
  end

  @doc "The longest (clock ms) these faults hold a datagram back: its latency, and a reordering's hold on top."
  @spec longest_hold(t()) :: non_neg_integer()
  def longest_hold(%__MODULE__{} = f), do: f.latency + if(f.reorder > 0, do: @reorder_max_ms, else: 0)

  defp flip(<<>>, r), do: {<<>>, r}

  defp flip(datagram, r) do
    {at, r} = :rand.uniform_s(byte_size(datagram), r)
    <<before::binary-size(at - 1), byte, rest::binary>> = datagram
    {<<before::binary, bxor(byte, 0x5A), rest::binary>>, r}
  end
end
