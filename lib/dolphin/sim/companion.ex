defmodule Dolphin.Sim.Companion do
  @moduledoc """
  A simulated vehicle's companion computer: a component of its own (191,
  MAV_COMP_ID_ONBOARD_COMPUTER) on the vehicle's system id, with a
  HEARTBEAT at 1 Hz (MAV_TYPE_ONBOARD_CONTROLLER) and its sensors' readings
  as NAMED_VALUE_FLOAT, each at its rate, with noise, from where the
  vehicle truly is in a `Dolphin.Sim.World` — as a real companion computer
  with a smoke sensor on a serial port reports them.

  The sensor models (`models/0`):

  | model | NAMED_VALUE_FLOAT | reads | noise (σ) by default |
  | --- | --- | --- | --- |
  | `smoke` | `SMOKE` | `Dolphin.Sim.World.smoke/3`, 0..1 | 0.02 |
  | `water_temp` | `WTEMP` | `Dolphin.Sim.World.water_temperature/3`, °C | 0.05 |
  | `range` | `RANGE` | `Dolphin.Sim.World.range/5`, metres | 0.05 |

  A pure model like `Dolphin.Sim.Copter`: `step/2` is given the vehicle as
  it is now, and returns what the companion says by then.
  """

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.{Copter, World}

  @compid 191

  @doc "The component id a companion computer speaks as (MAV_COMP_ID_ONBOARD_COMPUTER)."
  @spec compid() :: byte()
  def compid, do: @compid
  @models %{smoke: {"SMOKE", 0.02}, water_temp: {"WTEMP", 0.05}, range: {"RANGE", 0.05}}

  defstruct sensors: [], world: %World{}, period_ms: 500, noise: %{}, due: 0, heartbeat_due: 0, rand: nil

  @type model :: :smoke | :water_temp | :range
  @type t :: %__MODULE__{sensors: [model()], world: World.t(), period_ms: pos_integer(), noise: %{model() => float()}, due: integer(), heartbeat_due: integer(), rand: :rand.state()}

  @doc "The sensor models a simulated vehicle can carry."
  @spec models() :: [model()]
  def models, do: @models |> Map.keys() |> Enum.sort()

  @doc "The NAMED_VALUE_FLOAT name a model's readings carry."
  @spec value_name(model()) :: String.t()
  def value_name(model), do: @models |> Map.fetch!(model) |> elem(0)

  @doc """
  A companion with sensors `sensors` in `world`; options `rate_hz`, `noise`
  (σ for every sensor, or a map by model), each by default the world's
  `sensors` section's, else 2 Hz and each model's noise; `seed` (any term:
  each vehicle's its own, so that two vehicles side by side read apart).
  """
  @spec new([model()], World.t() | nil, keyword()) :: t()
  def new(sensors, world, opts \\ []) do
    world = world || %World{}
    noise = Keyword.get(opts, :noise) || Map.get(world.sensing, :noise)
    noise = Map.new(sensors, fn m -> {m, noise_of(noise, m)} end)
    rate = Keyword.get(opts, :rate_hz) || Map.get(world.sensing, :rate_hz, 2)

    %__MODULE__{
      sensors: Enum.uniq(sensors),
      world: world,
      period_ms: max(round(1000 / rate), 1),
      noise: noise,
      rand: :rand.seed_s(:exsss, {:erlang.phash2(Keyword.get(opts, :seed, 1)), 191, length(sensors)})
    }
  end

  defp noise_of(nil, model), do: @models |> Map.fetch!(model) |> elem(1)
  defp noise_of(%{} = by_model, model), do: Map.get(by_model, model) || noise_of(nil, model)
  defp noise_of(sigma, _model) when is_number(sigma), do: sigma * 1.0

  @typedoc "Where the vehicle truly is: degrees, metres above sea level, and the ground's height under it."
  @type place :: %{lat: float(), lon: float(), alt: float(), ground: float()}

  @doc "What the companion says up to the simulated vehicle's time now, `{compid, message}` oldest first."
  @spec step(t(), Copter.t()) :: {[{byte(), struct()}], t()}
  def step(%__MODULE__{} = c, %Copter{time_ms: now} = vehicle), do: step_at(c, now, Map.put(Copter.position(vehicle), :ground, Copter.ground(vehicle)))

  @doc """
  What the companion says up to `now` (the vehicle's boot time, ms) with
  the vehicle at `place`: what a sidecar computes for a vehicle it only
  hears (`Dolphin.Sim.Sidecar`).
  """
  @spec step_at(t(), integer(), place()) :: {[{byte(), struct()}], t()}
  def step_at(%__MODULE__{} = c, now, place) do
    # The vehicle's boot time went back (it rebooted): the timers start again.
    c = if now < c.due - c.period_ms or now < c.heartbeat_due - 1000, do: %{c | due: now, heartbeat_due: now}, else: c
    {beats, c} = heartbeat(c, now)

    if now >= c.due do
      {readings, rand} = Enum.map_reduce(c.sensors, c.rand, &reading(&1, &2, c, place, now))
      {beats ++ readings, %{c | rand: rand, due: now + c.period_ms}}
    else
      {beats, c}
    end
  end

  defp heartbeat(%{heartbeat_due: due} = c, now) when now >= due,
    do: {[{@compid, %M.Heartbeat{type: 18, autopilot: 8, base_mode: 0, custom_mode: 0, system_status: 4, mavlink_version: 3}}], %{c | heartbeat_due: now + 1000}}

  defp heartbeat(c, _now), do: {[], c}

  defp reading(model, rand, c, place, now) do
    {noise, rand} = :rand.normal_s(rand)
    value = truth(model, c.world, place) + noise * Map.fetch!(c.noise, model)
    value = if model in [:smoke, :range], do: max(value, 0.0), else: value
    {{@compid, %M.NamedValueFloat{time_boot_ms: now, name: value_name(model), value: value}}, rand}
  end

  defp truth(:smoke, world, p), do: World.smoke(world, p.lat, p.lon)
  defp truth(:water_temp, world, p), do: World.water_temperature(world, p.lat, p.lon)
  defp truth(:range, world, p), do: World.range(world, p.lat, p.lon, p.alt, p.ground)
end
