defmodule Dolphin.Vehicles.Retry do
  @moduledoc """
  How long the vehicle protocols (`Dolphin.Vehicles.CommandProtocol`,
  `Dolphin.Vehicles.MissionProtocol`) wait for an answer before asking again,
  and how many times they ask, from what the link shows: its round trip
  (`Dolphin.Vehicles.State`'s `link.rtt_ms`, and the samples a transfer takes)
  and its loss. A radio link that loses a third of the frames each way needs
  more tries than a cable, and one with a round trip of 5 ms should not wait
  a second and a half to resend.

      iex> Dolphin.Vehicles.Retry.attempts(0.0)
      5
      iex> Dolphin.Vehicles.Retry.attempts(0.51)
      21
  """

  alias Dolphin.Clock

  # The chance, at the link's loss, that every try of an exchange is lost.
  # A fleet sends thousands of commands a day: one in a million at most
  # should fail for want of tries.
  @give_up_chance 1.0e-6

  # A bad radio's round-trip loss, planned for until the link shows its own.
  @assumed_loss 0.3

  # However many tries the loss calls for, an exchange is not given up in
  # less than this much real time: a radio fades, and a loaded host stalls
  # its processes, for a second or more, and neither gets shorter with the
  # clock's speed-up (at 25x, 8 s of clock time is a third of a second).
  @least_patience_real_ms 5_000

  @doc """
  How many tries an exchange is given at a round-trip loss of `loss`
  (0.0..1.0, the share of requests that get no answer; nil: not measured
  yet, planned as 30 %): enough that all of them fail with a chance under
  one in a million (up to 79 % loss), between 5 and 60.
  """
  @spec attempts(float() | nil) :: pos_integer()
  def attempts(nil), do: attempts(@assumed_loss)
  def attempts(loss) when loss <= 0.0, do: 5
  def attempts(loss) when loss >= 1.0, do: 60
  def attempts(loss), do: (:math.log(@give_up_chance) / :math.log(loss)) |> Float.ceil() |> trunc() |> max(5) |> min(60)

  @doc """
  The least real time (ms) an exchange is given before it is given up: the
  patience `clock_ms` of clock time asks for, and never under 5 s of real
  time, whatever the speed-up.

      iex> Dolphin.Vehicles.Retry.patience_real_ms(8_000, 1)
      8000
      iex> Dolphin.Vehicles.Retry.patience_real_ms(8_000, 25)
      5000
  """
  @spec patience_real_ms(number(), number()) :: pos_integer()
  def patience_real_ms(clock_ms, speedup \\ Clock.speedup()), do: max(Clock.to_real_ms(clock_ms, speedup), @least_patience_real_ms)

  @doc """
  Where an exchange started with options `opts` counts its least patience
  from (`patient?/1`): now (monotonic real ms), or nil when the caller gave
  its `:attempts` — those are exact.
  """
  @spec patience_from(keyword()) :: integer() | nil
  def patience_from(opts), do: if(Keyword.has_key?(opts, :attempts), do: nil, else: System.monotonic_time(:millisecond))

  @doc """
  Whether an exchange whose latest progress (its first request, or the
  latest answer that brought something) was at `since` (monotonic real ms,
  nil: its attempts were given, no patience) is still within the least
  patience: a silence shorter than that is not given up on, however many
  tries went out in it. A link's loss is measured over the latest twenty
  seconds or so: one that has just got worse shows less loss than it has,
  and asks for fewer tries than it needs.
  """
  @spec patient?(integer() | nil) :: boolean()
  def patient?(nil), do: false
  def patient?(since), do: System.monotonic_time(:millisecond) - since < patience_real_ms(0)

  @doc """
  The round-trip loss of a link whose loss is `loss_in` towards the ground
  station and `loss_out` towards the vehicle (nil if either is unknown).

      iex> Dolphin.Vehicles.Retry.round_trip_loss(0.3, 0.3)
      0.51
  """
  @spec round_trip_loss(float() | nil, float() | nil) :: float() | nil
  def round_trip_loss(loss_in, loss_out) when is_number(loss_in) and is_number(loss_out), do: Float.round(1 - (1 - loss_in) * (1 - loss_out), 4)
  def round_trip_loss(_, _), do: nil

  @doc """
  The retransmission timeout (real ms) of round-trip samples (real ms):
  twice the 80th percentile of the latest ones, so that a stray slow answer
  (a busy vehicle, a radio's retry) does not slow every retry after it, as a
  mean would; `ceiling_ms` of clock time when no round trip is known, never
  more than that, never under `Dolphin.Clock`'s retry floor.

      iex> Dolphin.Vehicles.Retry.timeout([30, 40, 35, 38, 900], 1_000, 1)
      82
      iex> Dolphin.Vehicles.Retry.timeout([], 1_000, 1)
      1000
  """
  @spec timeout([number()], number(), number()) :: pos_integer()
  def timeout(samples, ceiling_ms, speedup \\ Clock.speedup())
  def timeout([], ceiling_ms, speedup), do: Clock.retry_real_ms(ceiling_ms, speedup)

  def timeout(samples, ceiling_ms, speedup) do
    sorted = Enum.sort(samples)
    p80 = Enum.at(sorted, trunc(0.8 * (length(sorted) - 1)))
    (2 * p80 + 2) |> round() |> max(Clock.retry_real_ms(0, speedup)) |> min(Clock.retry_real_ms(ceiling_ms, speedup))
  end

  @doc """
  How long (real ms) to wait for one answer to a request sent once (a
  COMMAND_ACK, a PARAM_VALUE): `longest` ms of clock time when the link's
  round trip `rtt_ms` is not known; else twice `timeout/2` of it, never
  under 250 ms of clock time (for the vehicle's own work) nor over `longest`.
  """
  @spec answer_wait(number(), number() | nil) :: pos_integer()
  def answer_wait(longest, rtt_ms) when is_number(rtt_ms), do: min(Clock.retry_real_ms(longest), max(2 * timeout([rtt_ms], longest), Clock.retry_real_ms(250)))
  def answer_wait(longest, _unknown), do: Clock.retry_real_ms(longest)
end
