defmodule Dolphin.MAVLink.MissionItems do
  @moduledoc """
  The two forms of a mission item: MISSION_ITEM (x, y as floats) and
  MISSION_ITEM_INT (x, y as integers: degrees × 10⁷ in global frames, metres
  × 10⁴ in local ones, as the MAVLink spec defines them).

      iex> alias Dolphin.MAVLink.Ardupilotmega, as: M
      iex> int = Dolphin.MAVLink.MissionItems.to_int(%M.MissionItem{frame: 3, x: 40.5, y: -7.25, z: 30.0})
      iex> {int.x, int.y, int.z}
      {405000000, -72500000, 30.0}
      iex> Dolphin.MAVLink.MissionItems.to_float(int).x
      40.5
  """

  alias Dolphin.MAVLink.Ardupilotmega, as: M

  # MAV_FRAMEs whose x, y are latitude and longitude.
  @global_frames [0, 3, 5, 6, 10, 11]

  @doc "The item as MISSION_ITEM_INT (unchanged if it is one); NaN or an infinity in x or y, which an integer cannot hold, becomes 0."
  @spec to_int(struct()) :: struct()
  def to_int(%M.MissionItemInt{} = item), do: item

  def to_int(%M.MissionItem{} = item) do
    scale = scale(item.frame)
    fields = Map.merge(Map.from_struct(item), %{x: scaled(item.x, scale), y: scaled(item.y, scale)})
    struct(M.MissionItemInt, fields)
  end

  @doc "The item as MISSION_ITEM (unchanged if it is one)."
  @spec to_float(struct()) :: struct()
  def to_float(%M.MissionItem{} = item), do: item

  def to_float(%M.MissionItemInt{} = item) do
    scale = scale(item.frame)
    struct(M.MissionItem, Map.merge(Map.from_struct(item), %{x: item.x / scale, y: item.y / scale}))
  end

  defp scale(frame) when frame in @global_frames, do: 1.0e7
  defp scale(_local), do: 1.0e4

  defp scaled(v, scale) when is_number(v), do: round(v * scale)
  defp scaled(_special, _scale), do: 0
end
