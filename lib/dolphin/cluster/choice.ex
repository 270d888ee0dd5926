defmodule Dolphin.Cluster.Choice do
  @moduledoc """
  Which station a controller talks to a vehicle through, when one or several
  ground stations hear it: pure functions, no processes (the mirror,
  `Dolphin.Cluster.Mirror`, holds the state and does the I/O).

  What the mirror knows of one vehicle on one station is a `t:hearing/0`:
  the station's latest view of it, how long ago (clock ms) the station last
  had a frame from it, and its link figures. A hearing is *fresh* when the
  station's vehicle is connected and was heard within `stale_ms`.

  The rules (`choose/3`):

    * the chosen station is kept while its hearing is fresh, unless another
      fresh one is clearly better (hysteresis: a loss lower by at least
      #{round(0.1 * 100)} points, or the same loss and a round trip shorter by
      half and by #{20} ms at least), so that two equally good radios do not
      make the route flap;
    * a chosen station that is no longer fresh gives way to the best fresh
      one: fresh first, then the lower link loss, then the shorter round trip;
    * with no fresh hearing the choice stays where it was: the vehicle is lost
      only when no station has it connected any more (`lost?/1`).

      iex> alias Dolphin.Cluster.Choice
      iex> v = %Dolphin.Vehicles.View{id: 1, type: :uav}
      iex> a = %{view: v, age_ms: 100, link: %{rtt_ms: 10, loss_in: 0.0, loss_out: 0.0}}
      iex> b = %{view: v, age_ms: 9_000, link: %{rtt_ms: 5, loss_in: 0.0, loss_out: 0.0}}
      iex> Choice.choose(%{a: a, b: b}, :b, stale_ms: 3_000)
      :a
      iex> Choice.choose(%{a: a, b: %{b | age_ms: 100}}, :b, stale_ms: 3_000)
      :b
  """

  alias Dolphin.Vehicles.View

  @typedoc "What one station says of one vehicle."
  @type hearing :: %{view: View.t(), age_ms: non_neg_integer() | nil, link: map()}

  # Hysteresis: how much better another station must be to take over from a fresh one.
  @loss_margin 0.1
  @rtt_margin_ms 20

  # Farther apart than one vehicle can be seen by two radios at the same moment.
  @max_apart_m 100.0

  @doc "The default age (clock ms) after which a station's hearing of a vehicle is stale."
  @spec stale_ms() :: pos_integer()
  def stale_ms, do: 3_000

  @doc "Whether a hearing is fresh (see the moduledoc)."
  @spec fresh?(hearing(), keyword()) :: boolean()
  def fresh?(%{view: view, age_ms: age}, opts \\ []) do
    view.connected? and (age == nil or age <= Keyword.get(opts, :stale_ms, stale_ms()))
  end

  @doc """
  The station to use among `hearings` (station => hearing), given the one
  chosen so far (`nil` for none) and option `:stale_ms`. (Stations whose
  views of one id are two vehicles, `conflict/2`, are not hearings of one
  vehicle: the mirror names them apart.)
  """
  @spec choose(%{term() => hearing()}, term() | nil, keyword()) :: term() | nil
  def choose(hearings, current, opts \\ []) do
    fresh = for {station, h} <- hearings, fresh?(h, opts), do: {station, h}
    current_h = Map.get(hearings, current)

    cond do
      current_h && fresh?(current_h, opts) -> keep_or_switch(current, current_h, fresh)
      fresh != [] -> fresh |> Enum.min_by(fn {station, h} -> {score(h), station} end) |> elem(0)
      current_h -> current
      hearings == %{} -> nil
      # Nobody hears it fresh and the chosen station is gone: the one that had it last.
      true -> hearings |> Enum.min_by(fn {station, h} -> {h.age_ms || 0, station} end) |> elem(0)
    end
  end

  defp keep_or_switch(current, current_h, fresh) do
    case Enum.min_by(fresh, fn {station, h} -> {score(h), station} end) do
      {^current, _} -> current
      {station, h} -> if clearly_better?(h, current_h), do: station, else: current
    end
  end

  defp score(h), do: {loss(h.link), rtt(h.link)}

  # Only measured figures of both can take a fresh station's place: a link
  # not measured yet is no evidence against it.
  defp clearly_better?(h, current) do
    {loss_a, loss_b} = {loss(h.link), loss(current.link)}
    {rtt_a, rtt_b} = {rtt(h.link), rtt(current.link)}
    measured? = fn a, b -> a != nil and b != nil end

    cond do
      measured?.(measured_loss(h.link), measured_loss(current.link)) and loss_a + @loss_margin <= loss_b -> true
      not measured?.(measured_rtt(h.link), measured_rtt(current.link)) -> false
      true -> abs(loss_a - loss_b) < @loss_margin and rtt_a + @rtt_margin_ms <= rtt_b and rtt_a * 2 <= rtt_b
    end
  end

  defp measured_loss(link), do: if(loss(link) == 1.0 and not is_number(Map.get(link, :loss_in)), do: nil, else: loss(link))
  defp measured_rtt(link), do: Map.get(link, :rtt_ms)

  # Unmeasured counts as worst, so that a measured link is preferred.
  defp loss(%{loss_in: a, loss_out: b}) when is_number(a) and is_number(b), do: max(a, b)
  defp loss(%{loss_in: a}) when is_number(a), do: a
  defp loss(_), do: 1.0

  defp rtt(%{rtt_ms: r}) when is_number(r), do: r
  defp rtt(_), do: 1_000_000

  @doc "Whether no station has the vehicle connected (every station lost it, or none is left)."
  @spec lost?(%{term() => hearing()}) :: boolean()
  def lost?(hearings), do: not Enum.any?(hearings, fn {_station, h} -> h.view.connected? end)

  @doc """
  Whether two views of one vehicle id, from two stations, are two different
  vehicles: `{:conflict, why}` when their autopilots' unique ids differ
  (both known and not 0), their classes differ (both known) or, both with a
  position, they are farther apart than #{round(@max_apart_m)} m; `:same`
  otherwise.

      iex> v = %Dolphin.Vehicles.View{id: 3, type: :uav}
      iex> Dolphin.Cluster.Choice.conflict(v, %{v | type: :usv})
      {:conflict, "one station hears a uav, the other a usv"}
      iex> Dolphin.Cluster.Choice.conflict(v, %{v | type: nil})
      :same
      iex> Dolphin.Cluster.Choice.conflict(%{v | uid: 7}, %{v | uid: 9})
      {:conflict, "the two stations hear two autopilots (unique ids 7 and 9)"}
  """
  @spec conflict(View.t(), View.t()) :: :same | {:conflict, String.t()}
  def conflict(%View{} = a, %View{} = b) do
    cond do
      a.uid not in [nil, 0] and b.uid not in [nil, 0] and a.uid != b.uid ->
        {:conflict, "the two stations hear two autopilots (unique ids #{a.uid} and #{b.uid})"}

      a.type != nil and b.type != nil and a.type != b.type ->
        {:conflict, "one station hears a #{a.type}, the other a #{b.type}"}

      a.position != nil and b.position != nil and Dolphin.Geo.distance(a.position, b.position) > @max_apart_m ->
        {:conflict, "the two stations place it #{round(Dolphin.Geo.distance(a.position, b.position))} m apart"}

      true ->
        :same
    end
  end
end
