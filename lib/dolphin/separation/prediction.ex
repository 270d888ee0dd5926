defmodule Dolphin.Separation.Prediction do
  @moduledoc """
  Whether two vehicles moving in a straight line at constant velocity will
  come closer than a least separation within a few seconds: the live
  monitor's judgement (`Dolphin.Separation`), pure.

  A separation is lost when the two are closer than `horizontal` metres
  across *and* closer than `vertical` metres in height at the same moment
  (as the pre-flight check judges it: one vehicle 15 m above another is
  apart with the default 20 m / 10 m).

  Each vehicle is `{{north, east, up}, {v_north, v_east, v_up}}`: metres in
  one local frame and metres per second.

      iex> a = {{0.0, 0.0, 30.0}, {10.0, 0.0, 0.0}}
      iex> b = {{100.0, 0.0, 30.0}, {-10.0, 0.0, 0.0}}
      iex> Dolphin.Separation.Prediction.conflict(a, b, %{horizontal: 20.0, vertical: 10.0}, 10)
      {:conflict, 4.0, 0.0}
      iex> Dolphin.Separation.Prediction.conflict(a, b, %{horizontal: 20.0, vertical: 10.0}, 3)
      :clear
      iex> parting = {{5.0, 0.0, 30.0}, {15.0, 0.0, 0.0}}
      iex> Dolphin.Separation.Prediction.conflict(a, parting, %{horizontal: 20.0, vertical: 10.0}, 10)
      :clear
      iex> above = {{100.0, 0.0, 45.0}, {-10.0, 0.0, 0.0}}
      iex> Dolphin.Separation.Prediction.conflict(a, above, %{horizontal: 20.0, vertical: 10.0}, 10)
      :clear
  """

  @type motion :: {{number(), number(), number()}, {number(), number(), number()}}
  @type limits :: %{horizontal: number(), vertical: number()}

  @doc """
  `{:conflict, in_s, closest}` when, within `horizon` seconds, the two come
  within both limits at once: `in_s` the seconds until they first do (0:
  they are already, and are not moving apart), `closest` the least
  distance across while they are; else `:clear` (apart, or within the
  limits already and moving apart).
  """
  @spec conflict(motion(), motion(), limits(), number()) :: {:conflict, float(), float()} | :clear
  def conflict({{pn, pe, pu}, {vn, ve, vu}} = a, {{qn, qe, qu}, {wn, we, wu}} = b, %{horizontal: h, vertical: v} = limits, horizon) do
    {dn, de, du} = {qn - pn, qe - pe, qu - pu}
    {rn, re, ru} = {wn - vn, we - ve, wu - vu}
    # Across: |d + r t|² < h², a quadratic in t; in height: |du + ru t| < v.
    across = below_quadratic(rn * rn + re * re, 2 * (dn * rn + de * re), dn * dn + de * de - h * h)
    height = below_linear(du, ru, v)

    case intersect(intersect(across, height), {0.0, horizon * 1.0}) do
      nil ->
        :clear

      # Too close already, but parting (scaled by the limits, so that a metre
      # in height counts as much as its share of the separation): going on apart.
      {from, to} when from == 0 ->
        # (Within already, not merely from the limit's edge on.)
        within? = dn * dn + de * de < h * h and abs(du) < v
        if within? and parting?(a, b, limits), do: :clear, else: closest(dn, de, rn, re, from, to)

      {from, to} ->
        closest(dn, de, rn, re, from, to)
    end
  end

  # The least distance across in [from, to]: at the vertex of the quadratic, or an end.
  defp closest(dn, de, rn, re, from, to) do
    a = rn * rn + re * re
    t = if a == 0, do: from, else: min(max(-(dn * rn + de * re) / a, from), to)
    {cn, ce} = {dn + rn * t, de + re * t}
    {:conflict, from, :math.sqrt(cn * cn + ce * ce)}
  end

  @doc """
  Whether two vehicles are moving apart, counting a metre in height as its
  share of the vertical separation against a metre across as its share of
  the horizontal one.

      iex> Dolphin.Separation.Prediction.parting?({{0, 0, 30}, {10, 0, 0}}, {{5, 0, 30}, {15, 0, 0}}, %{horizontal: 20, vertical: 10})
      true
  """
  @spec parting?(motion(), motion(), limits()) :: boolean()
  def parting?({{pn, pe, pu}, {vn, ve, vu}}, {{qn, qe, qu}, {wn, we, wu}}, %{horizontal: h, vertical: v}),
    do: ((qn - pn) * (wn - vn) + (qe - pe) * (we - ve)) / (h * h) + (qu - pu) * (wu - vu) / (v * v) > 0

  @doc """
  The horizontal and vertical distance between two positions, `{across, height}`.

      iex> Dolphin.Separation.Prediction.apart({{0, 0, 10}, {0, 0, 0}}, {{3, 4, 4}, {1, 0, 0}})
      {5.0, 6}
  """
  @spec apart(motion(), motion()) :: {float(), number()}
  def apart({{pn, pe, pu}, _}, {{qn, qe, qu}, _}), do: {:math.sqrt((qn - pn) * (qn - pn) + (qe - pe) * (qe - pe)), abs(qu - pu)}

  @doc """
  Whether two positions are apart: at least one of the two limits kept.

      iex> Dolphin.Separation.Prediction.apart?({{0, 0, 10}, {0, 0, 0}}, {{3, 4, 25}, {0, 0, 0}}, %{horizontal: 20, vertical: 10})
      true
  """
  @spec apart?(motion(), motion(), limits()) :: boolean()
  def apart?(a, b, %{horizontal: h, vertical: v}) do
    {across, height} = apart(a, b)
    across >= h or height >= v
  end

  # The open interval of t where a t² + b t + c < 0 (a >= 0): all t, none (nil), or between the roots.
  defp below_quadratic(a, _b, c) when a == 0, do: if(c < 0, do: :all, else: nil)

  defp below_quadratic(a, b, c) do
    disc = b * b - 4 * a * c

    if disc <= 0 do
      nil
    else
      root = :math.sqrt(disc)
      {(-b - root) / (2 * a), (-b + root) / (2 * a)}
    end
  end

  # Where |d + r t| < limit.
  defp below_linear(d, r, limit) when r == 0, do: if(abs(d) < limit, do: :all, else: nil)

  defp below_linear(d, r, limit) do
    {t1, t2} = {(-limit - d) / r, (limit - d) / r}
    {min(t1, t2), max(t1, t2)}
  end

  defp intersect(nil, _), do: nil
  defp intersect(_, nil), do: nil
  defp intersect(:all, other), do: other
  defp intersect(other, :all), do: other

  defp intersect({a1, b1}, {a2, b2}) do
    {from, to} = {max(a1, a2), min(b1, b2)}
    if from < to, do: {from * 1.0, to * 1.0}, else: nil
  end
end
