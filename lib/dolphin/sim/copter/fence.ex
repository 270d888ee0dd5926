defmodule Dolphin.Sim.Copter.Fence do
  @moduledoc false
  # The simulated vehicle's geofence, as ArduCopter keeps one
  # (docs/ardupilot.md, "Fences"): with FENCE_ENABLE 1 it is checked every
  # step against the fence list of the mission protocol (its zones, judged
  # by Dolphin.Geo.Shapes as the pre-flight check judges them: inside every
  # inclusion zone, outside every exclusion zone) and the altitude band
  # FENCE_ALT_MAX / FENCE_ALT_MIN (above home), by the FENCE_TYPE bits. A new
  # breach, armed and in the air: "Polygon fence breached" (or "Max Alt",
  # "Min Alt"; several joined by "and"), FENCE_ACTION taken (0 report, 1 RTL,
  # 2 LAND, 4 BRAKE), "Manual recovery started", a FENCE_STATUS at once; for
  # 10 s after, new breaches are counted and not acted on. Back inside:
  # "Fence breach cleared". FENCE_STATUS (162) reports it while the fence is
  # enabled.

  import Dolphin.Sim.Copter, only: [text: 3, in_air?: 1, home_alt: 1, say: 2]

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.{Copter, MissionServer}
  alias Dolphin.Geo
  alias Dolphin.Sim.Copter.Modes

  @boundary 4
  @max_alt 1
  @min_alt 8
  @recovery_ms 10_000
  # FENCE_ACTION's numbers, as each firmware reads them.
  @actions %{1 => :rtl, 2 => :land, 4 => :brake}
  @ground_actions %{1 => :rtl, 2 => :hold}

  @doc false
  @spec step(Copter.t()) :: Copter.t()
  def step(c) do
    if enabled?(c), do: check(c), else: c
  end

  @doc false
  def enabled?(c), do: Map.get(c.params, "FENCE_ENABLE", 0) == 1

  @doc false
  # ArduRover's avoidance: a rover or boat under way with its fence enabled
  # stops FENCE_MARGIN short of it (an exclusion zone's edge, the inclusion
  # zone's) instead of breaching it, and stays there in its mode, saying
  # nothing (measured on ArduRover SITL: 78 m along a leg into a zone 80 m
  # out). `before` is the vehicle before this step's move.
  @spec avoid(Copter.t(), Copter.t()) :: Copter.t()
  def avoid(%{config: %{airframe: airframe}} = c, before) when airframe in [:rover, :boat] do
    speed = :math.sqrt(c.vn * c.vn + c.ve * c.ve)

    if enabled?(c) and c.armed and speed > 0.01 and Bitwise.band(types(c), @boundary) != 0 do
      margin = Map.get(c.params, "FENCE_MARGIN", 2)
      {zones, c} = zones(c)
      ahead = Geo.offset(Copter.location(c), c.vn / speed * margin, c.ve / speed * margin)
      if Dolphin.Fence.breach(zones, ahead) != nil, do: %{c | n: before.n, e: before.e, vn: 0.0, ve: 0.0}, else: c
    else
      c
    end
  end

  def avoid(c, _before), do: c

  @doc false
  # FENCE_STATUS: breach_type 3 the boundary, 2 the ceiling, 1 the floor.
  def status(c) do
    f = c.fence

    type =
      cond do
        Bitwise.band(f.bits, @boundary) != 0 -> 3
        Bitwise.band(f.bits, @max_alt) != 0 -> 2
        Bitwise.band(f.bits, @min_alt) != 0 -> 1
        true -> 0
      end

    %M.FenceStatus{breach_status: if(f.bits != 0, do: 1, else: 0), breach_count: f.count, breach_type: type, breach_time: f.time_ms, breach_mitigation: 1}
  end

  defp check(c) do
    {zones, c} = zones(c)
    types = types(c)
    height = c.alt - home_alt(c)
    here = Copter.location(c)

    bits =
      Enum.sum([
        if(Bitwise.band(types, @boundary) != 0 and Dolphin.Fence.breach(zones, here) != nil, do: @boundary, else: 0),
        if(Bitwise.band(types, @max_alt) != 0 and height >= Map.get(c.params, "FENCE_ALT_MAX", 100), do: @max_alt, else: 0),
        if(Bitwise.band(types, @min_alt) != 0 and in_air?(c) and height <= Map.get(c.params, "FENCE_ALT_MIN", -10), do: @min_alt, else: 0)
      ])

    new = Bitwise.band(bits, Bitwise.bnot(c.fence.bits))

    cond do
      new != 0 -> breached(c, bits, new)
      bits == 0 and c.fence.bits != 0 -> cleared(c)
      true -> %{c | fence: %{c.fence | bits: bits}}
    end
  end

  defp breached(c, bits, new) do
    episode? = c.fence.bits == 0
    fence = %{c.fence | bits: bits, count: c.fence.count + 1, time_ms: if(episode?, do: c.time_ms, else: c.fence.time_ms)}
    c = %{c | fence: fence}

    if c.armed and in_air?(c) and c.time_ms >= fence.recovery_until do
      c = text(c, 5, "#{names(new)} breached")
      c = act(c, actions(c)[round(Map.get(c.params, "FENCE_ACTION", 1))])
      c = %{c | fence: %{c.fence | recovery_until: c.time_ms + @recovery_ms}}
      c |> text(6, "Manual recovery started") |> say(status(c))
    else
      c
    end
  end

  defp cleared(c) do
    c = %{c | fence: %{c.fence | bits: 0}}
    if in_air?(c), do: text(c, 5, "Fence breach cleared"), else: c
  end

  defp types(c), do: round(Map.get(c.params, "FENCE_TYPE", 7))

  defp actions(%{config: %{airframe: airframe}}) when airframe in [:rover, :boat], do: @ground_actions
  defp actions(_c), do: @actions

  defp act(c, nil), do: c

  defp act(c, mode) do
    {_, c} = Modes.set_mode_named(c, mode)
    c
  end

  defp names(bits) do
    [{@boundary, "Polygon"}, {@max_alt, "Max Alt"}, {@min_alt, "Min Alt"}]
    |> Enum.filter(fn {bit, _} -> Bitwise.band(bits, bit) != 0 end)
    |> Enum.map_join(" and ", &elem(&1, 1))
    |> Kernel.<>(if(Bitwise.band(bits, bits - 1) != 0, do: " fences", else: " fence"))
  end

  # The zones of the fence list, parsed once per list.
  defp zones(c) do
    items = MissionServer.items(c.missions, 1)

    case c.fence.zones do
      {^items, zones} -> {zones, c}
      _ -> with zones = Dolphin.Fence.from_items(items), do: {zones, %{c | fence: %{c.fence | zones: {items, zones}}}}
    end
  end
end
