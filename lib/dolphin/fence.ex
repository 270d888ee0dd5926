defmodule Dolphin.Fence do
  @moduledoc """
  Where vehicles may fly: inclusion zones they must stay in, exclusion zones
  (no-fly zones) they must stay out of, an altitude band, what the autopilot
  does on a breach, and the rally points it may return to. Plain data, made
  by `new/1` (or the script's `fence do ... end`, `Dolphin.DSL.Fence`) and
  judged with the pure functions of `Dolphin.Geo.Shapes`.

  Fields:

    * `include` — polygons and circles (`Dolphin.Geo.Polygon`,
      `Dolphin.Geo.Circle`) the vehicle must stay inside: inside every one
      of them, as ArduPilot judges several inclusion zones;
    * `exclude` — polygons and circles it must stay out of;
    * `max_altitude`, `min_altitude` — metres above home (nil: none);
    * `on_breach` — what the autopilot does when the vehicle breaches it:
      `:rtl` (the default: return home, or land if it cannot), `:land`,
      `:hold` (brake, or loiter where the airframe cannot stand still) or
      `:report` (only say so);
    * `rally` — locations a return may go to instead of home.

      iex> home = Dolphin.Geo.location(38.43462, -8.86118, 0)
      iex> {:ok, area} = Dolphin.Geo.Shapes.circle(home, 500)
      iex> {:ok, fence} = Dolphin.Fence.new(include: [area], max_altitude: 120, on_breach: :land)
      iex> {fence.max_altitude, fence.on_breach}
      {120.0, :land}
      iex> Dolphin.Fence.new(max_altitude: 10, min_altitude: 30)
      {:error, "the fence's altitude band is upside down: min_altitude 30 m is above max_altitude 10 m"}
  """

  alias Dolphin.Geo.{Circle, Location, Polygon, Shapes}

  defstruct include: [], exclude: [], max_altitude: nil, min_altitude: nil, on_breach: :rtl, rally: []

  @type shape :: Polygon.t() | Circle.t()
  @type t :: %__MODULE__{
          include: [shape()],
          exclude: [shape()],
          max_altitude: float() | nil,
          min_altitude: float() | nil,
          on_breach: :rtl | :land | :hold | :report,
          rally: [Location.t()]
        }

  @actions [:rtl, :land, :hold, :report]

  @doc "The breach actions, as `on_breach:` names them."
  @spec actions() :: [atom()]
  def actions, do: @actions

  @doc """
  A fence from options (the fields above), or why it cannot be one: a zone
  that is not a polygon or circle, an altitude that is not a number of
  metres, an upside-down band, an unknown breach action, a rally point
  that is not a location.
  """
  @spec new(keyword()) :: {:ok, t()} | {:error, String.t()}
  def new(opts) when is_list(opts) do
    with :ok <- known_keys(opts),
         {:ok, include} <- shapes(opts, :include),
         {:ok, exclude} <- shapes(opts, :exclude),
         {:ok, max} <- altitude(opts, :max_altitude),
         {:ok, min} <- altitude(opts, :min_altitude),
         :ok <- band(min, max),
         {:ok, action} <- action(Keyword.get(opts, :on_breach, :rtl)),
         {:ok, rally} <- rally(Keyword.get(opts, :rally, [])) do
      {:ok, %__MODULE__{include: include, exclude: exclude, max_altitude: max, min_altitude: min, on_breach: action, rally: rally}}
    end
  end

  @doc "As `new/1`, raising `ArgumentError` with the reason."
  @spec new!(keyword()) :: t()
  def new!(opts) do
    case new(opts) do
      {:ok, fence} -> fence
      {:error, why} -> raise ArgumentError, why
    end
  end

  @doc "The fence with rally points `points` (locations), or why they are not."
  @spec put_rally(t(), [Location.t()]) :: {:ok, t()} | {:error, String.t()}
  def put_rally(%__MODULE__{} = fence, points) do
    with {:ok, rally} <- rally(points), do: {:ok, %{fence | rally: rally}}
  end

  @doc """
  What is wrong with flying `fence` from `home`: an inclusion zone that does
  not contain home (the vehicle would be in breach before it starts), an
  exclusion zone that does, a rally point outside the fence. Empty when
  nothing is.
  """
  @spec problems(t(), Location.t()) :: [String.t()]
  def problems(%__MODULE__{} = fence, %Location{} = home) do
    outside = for {zone, i} <- Enum.with_index(fence.include, 1), not Shapes.contains?(zone, home), do: "inclusion zone #{i} (#{inspect(zone)}) does not contain home (#{inspect(home)})"
    inside = for {zone, i} <- Enum.with_index(fence.exclude, 1), Shapes.contains?(zone, home), do: "exclusion zone #{i} (#{inspect(zone)}) contains home (#{inspect(home)})"
    rally = for {point, i} <- Enum.with_index(fence.rally, 1), why = breach(fence, point), do: "rally point #{i} (#{inspect(point)}) is #{why}"
    outside ++ inside ++ rally
  end

  @doc """
  Why `point` breaches the fence horizontally ("outside inclusion zone 1",
  "inside exclusion zone 2"), or nil when it does not.
  """
  @spec breach(t(), Location.t()) :: String.t() | nil
  def breach(%__MODULE__{} = fence, %Location{} = point) do
    Enum.find_value(Enum.with_index(fence.include, 1), fn {zone, i} -> if not Shapes.contains?(zone, point), do: "outside inclusion zone #{i}" end) ||
      Enum.find_value(Enum.with_index(fence.exclude, 1), fn {zone, i} -> if Shapes.contains?(zone, point), do: "inside exclusion zone #{i}" end)
  end

  @doc "Whether the fence says nothing at all (no zone, no band, no rally point)."
  @spec empty?(t()) :: boolean()
  def empty?(%__MODULE__{include: [], exclude: [], max_altitude: nil, min_altitude: nil, rally: []}), do: true
  def empty?(%__MODULE__{}), do: false

  @doc """
  The fence as the items of the mission protocol's fence and rally lists
  (MISSION_ITEM_INT, `mission_type` 1 and 2, seq from 0): a polygon is one
  item per corner (MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION or _EXCLUSION,
  param1 its corner count), a circle one item (..._CIRCLE_INCLUSION or
  _EXCLUSION, param1 its radius), in frame GLOBAL_INT; a rally point is
  MAV_CMD_NAV_RALLY_POINT at its height above `home`, in frame
  GLOBAL_RELATIVE_ALT_INT.

      iex> home = Dolphin.Geo.location(38.43462, -8.86118, 0)
      iex> {:ok, zone} = Dolphin.Geo.Shapes.circle(home, 500)
      iex> %{fence: [circle], rally: [point]} = Dolphin.Fence.to_items(%Dolphin.Fence{include: [zone], rally: [Dolphin.Geo.offset(home, 100, 0, 30)]}, home)
      iex> {circle.command, circle.param1, circle.mission_type, point.command, point.z, point.mission_type}
      {5003, 500.0, 1, 5100, 30.0, 2}
  """
  @spec to_items(t(), Location.t()) :: %{fence: [struct()], rally: [struct()]}
  def to_items(%__MODULE__{} = fence, %Location{} = home) do
    zones = Enum.flat_map(fence.include, &zone_items(&1, :inclusion)) ++ Enum.flat_map(fence.exclude, &zone_items(&1, :exclusion))
    rally = for p <- fence.rally, do: item(5100, 6, p, p.h - home.h, 0.0, 2)
    %{fence: numbered(zones), rally: numbered(rally)}
  end

  @doc """
  The zones of a fence list as the vehicle keeps it (`to_items/2`'s fence
  items, or any maps with `command`, `x`, `y` in degE7 and `param1`): a
  polygon is its run of corners (param1 of them), a circle one item. What
  is not a zone (a return point), or a zone that cannot be one, is left out.

      iex> home = Dolphin.Geo.location(38.43462, -8.86118, 0)
      iex> {:ok, zone} = Dolphin.Geo.Shapes.polygon(for {n, e} <- [{0, 0}, {0, 100}, {100, 0}], do: Dolphin.Geo.offset(home, n, e))
      iex> %{fence: items} = Dolphin.Fence.to_items(%Dolphin.Fence{exclude: [zone]}, home)
      iex> [%Dolphin.Geo.Polygon{points: corners}] = Dolphin.Fence.from_items(items).exclude
      iex> length(corners)
      3
  """
  @spec from_items([map()]) :: t()
  def from_items(items), do: zones(items, %__MODULE__{})

  defp zones([], fence), do: fence

  defp zones([%{command: c, param1: n} | _] = items, fence) when c in [5001, 5002] do
    {corners, rest} = Enum.split(items, max(trunc(n), 1))
    zones(rest, add_zone(fence, if(c == 5001, do: :include, else: :exclude), Shapes.polygon(Enum.map(corners, &item_point/1))))
  end

  defp zones([%{command: c, param1: r} = item | rest], fence) when c in [5003, 5004],
    do: zones(rest, add_zone(fence, if(c == 5003, do: :include, else: :exclude), Shapes.circle(item_point(item), r)))

  defp zones([_other | rest], fence), do: zones(rest, fence)

  defp add_zone(fence, side, {:ok, zone}), do: Map.update!(fence, side, &(&1 ++ [zone]))
  defp add_zone(fence, _side, {:error, _}), do: fence

  defp item_point(item), do: Dolphin.Geo.location(item.x / 1.0e7, item.y / 1.0e7, 0)

  @vertex %{inclusion: 5001, exclusion: 5002}
  @circle %{inclusion: 5003, exclusion: 5004}

  defp zone_items(%Polygon{points: points}, side), do: for(p <- points, do: item(@vertex[side], 5, p, 0.0, length(points) * 1.0, 1))
  defp zone_items(%Circle{centre: c, radius: r}, side), do: [item(@circle[side], 5, c, 0.0, r, 1)]

  defp item(command, frame, %Location{lat: lat, lon: lon}, z, param1, type) do
    %Dolphin.MAVLink.Ardupilotmega.MissionItemInt{
      command: command,
      frame: frame,
      x: round(lat * 1.0e7),
      y: round(lon * 1.0e7),
      z: z * 1.0,
      param1: param1,
      param2: 0.0,
      param3: 0.0,
      param4: 0.0,
      autocontinue: 1,
      current: 0,
      mission_type: type
    }
  end

  defp numbered(items), do: items |> Enum.with_index() |> Enum.map(fn {item, seq} -> %{item | seq: seq} end)

  @doc """
  The FENCE_TYPE bits that enable what the fence has: 1 its ceiling, 4 its
  zones (polygons and circles alike), 8 its floor.
  """
  @spec type_bits(t()) :: non_neg_integer()
  def type_bits(%__MODULE__{} = fence) do
    Enum.sum([
      if(fence.max_altitude, do: 1, else: 0),
      if(fence.include != [] or fence.exclude != [], do: 4, else: 0),
      if(fence.min_altitude, do: 8, else: 0)
    ])
  end

  @keys [:include, :exclude, :max_altitude, :min_altitude, :on_breach, :rally]

  defp known_keys(opts) do
    case Enum.uniq(Keyword.keys(opts)) -- @keys do
      [] -> :ok
      [key | _] -> {:error, "a fence has no #{inspect(key)} (it has #{Enum.map_join(@keys, ", ", &inspect/1)})"}
    end
  end

  defp shapes(opts, key) do
    shapes = opts |> Keyword.get_values(key) |> List.flatten()

    case Enum.reject(shapes, &(match?(%Polygon{}, &1) or match?(%Circle{}, &1))) do
      [] -> {:ok, shapes}
      [other | _] -> {:error, "#{key} takes a polygon(...) or a circle(...), got: #{inspect(other)}"}
    end
  end

  defp altitude(opts, key) do
    case Keyword.get(opts, key) do
      nil -> {:ok, nil}
      n when is_number(n) -> {:ok, n * 1.0}
      other -> {:error, "#{key} is a number of metres above home, got: #{inspect(other)}"}
    end
  end

  defp band(min, max) when is_number(min) and is_number(max) and min >= max,
    do: {:error, "the fence's altitude band is upside down: min_altitude #{metres(min)} is above max_altitude #{metres(max)}"}

  defp band(_min, _max), do: :ok

  defp action(action) when action in @actions, do: {:ok, action}
  defp action(other), do: {:error, "on_breach is one of #{Enum.map_join(@actions, ", ", &inspect/1)}, got: #{inspect(other)}"}

  defp rally(points) when is_list(points) do
    case Enum.reject(points, &match?(%Location{}, &1)) do
      [] -> {:ok, points}
      [other | _] -> {:error, "a rally point is a location, got: #{inspect(other)}"}
    end
  end

  defp rally(other), do: {:error, "rally takes a list of locations, got: #{inspect(other)}"}

  defp metres(m) when m == trunc(m), do: "#{trunc(m)} m"
  defp metres(m), do: "#{m} m"
end
