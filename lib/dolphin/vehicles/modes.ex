defmodule Dolphin.Vehicles.Modes do
  @moduledoc """
  Flight modes by name, from a HEARTBEAT's `custom_mode`, for ArduPilot's
  vehicles (Copter, Plane, Rover/Boat, Sub) and PX4.

      iex> Dolphin.Vehicles.Modes.name(:ardupilot, 2, 4)
      :guided
      iex> Dolphin.Vehicles.Modes.number(:ardupilot, 2, :brake)
      {:ok, 17}
      iex> Dolphin.Vehicles.Modes.name(:px4, 2, 0x04040000)
      :mission
  """

  import Bitwise

  @copter %{
    0 => :stabilize, 1 => :acro, 2 => :alt_hold, 3 => :auto, 4 => :guided, 5 => :loiter, 6 => :rtl,
    7 => :circle, 9 => :land, 11 => :drift, 13 => :sport, 14 => :flip, 15 => :autotune, 16 => :poshold,
    17 => :brake, 18 => :throw, 19 => :avoid_adsb, 20 => :guided_nogps, 21 => :smart_rtl, 22 => :flowhold,
    23 => :follow, 24 => :zigzag, 25 => :systemid, 26 => :autorotate, 27 => :auto_rtl, 28 => :turtle
  }

  @plane %{
    0 => :manual, 1 => :circle, 2 => :stabilize, 3 => :training, 4 => :acro, 5 => :fbwa, 6 => :fbwb,
    7 => :cruise, 8 => :autotune, 10 => :auto, 11 => :rtl, 12 => :loiter, 13 => :takeoff, 14 => :avoid_adsb,
    15 => :guided, 17 => :qstabilize, 18 => :qhover, 19 => :qloiter, 20 => :qland, 21 => :qrtl,
    22 => :qautotune, 23 => :qacro, 24 => :thermal, 25 => :loiter_alt_qland
  }

  @rover %{
    0 => :manual, 1 => :acro, 3 => :steering, 4 => :hold, 5 => :loiter, 6 => :follow, 7 => :simple,
    8 => :dock, 9 => :circle, 10 => :auto, 11 => :rtl, 12 => :smart_rtl, 15 => :guided, 16 => :initialising
  }

  @sub %{
    0 => :stabilize, 1 => :acro, 2 => :alt_hold, 3 => :auto, 4 => :guided, 7 => :circle, 9 => :surface,
    16 => :poshold, 19 => :manual, 20 => :motor_detect, 21 => :surftrak
  }

  # PX4: main mode in bits 16..23 of custom_mode, sub mode (of AUTO) in bits 24..31.
  @px4_main %{1 => :manual, 2 => :altctl, 3 => :posctl, 5 => :acro, 6 => :offboard, 7 => :stabilized, 8 => :rattitude}
  @px4_auto %{1 => :ready, 2 => :takeoff, 3 => :loiter, 4 => :mission, 5 => :rtl, 6 => :land, 8 => :follow_target, 9 => :precland}

  @fixed_wing [1, 16, 19, 20, 21, 22, 23, 24, 25, 28]
  @ground [10, 11]
  @submarine [12]

  @type autopilot :: :ardupilot | :px4 | :other

  @doc "The mode's name, or `{:custom, custom_mode}` when it is not in the table."
  @spec name(autopilot(), non_neg_integer(), non_neg_integer()) :: atom() | {:custom, non_neg_integer()}
  def name(:px4, _type, custom_mode) do
    main = custom_mode >>> 16 &&& 0xFF
    sub = custom_mode >>> 24 &&& 0xFF
    found = if main == 4, do: Map.get(@px4_auto, sub), else: Map.get(@px4_main, main)
    found || {:custom, custom_mode}
  end

  def name(:ardupilot, type, custom_mode), do: Map.get(table(type), custom_mode, {:custom, custom_mode})
  def name(_other, _type, custom_mode), do: {:custom, custom_mode}

  @doc """
  The number(s) that select a mode by name: ArduPilot's `custom_mode`, or PX4's
  `{main_mode, sub_mode}` (as MAV_CMD_DO_SET_MODE's param2 and param3 take them).
  """
  @spec number(:ardupilot | :px4, non_neg_integer(), atom()) ::
          {:ok, non_neg_integer() | {non_neg_integer(), non_neg_integer()}} | :error
  def number(:px4, _type, name) do
    case Enum.find(@px4_main, fn {_n, mode} -> mode == name end) do
      {main, _} ->
        {:ok, {main, 0}}

      nil ->
        case Enum.find(@px4_auto, fn {_n, mode} -> mode == name end) do
          {sub, _} -> {:ok, {4, sub}}
          nil -> :error
        end
    end
  end

  def number(:ardupilot, type, name) do
    case Enum.find(table(type), fn {_n, mode} -> mode == name end) do
      {n, _} -> {:ok, n}
      nil -> :error
    end
  end

  def number(_other, _type, _name), do: :error

  @doc "The mode names of a vehicle type."
  @spec names(:ardupilot | :px4, non_neg_integer()) :: [atom()]
  def names(:ardupilot, type), do: table(type) |> Enum.sort() |> Enum.map(&elem(&1, 1))
  def names(:px4, _type), do: Map.values(@px4_main) ++ Map.values(@px4_auto)
  def names(_other, _type), do: []

  defp table(type) when type in @fixed_wing, do: @plane
  defp table(type) when type in @ground, do: @rover
  defp table(type) when type in @submarine, do: @sub
  defp table(_copter), do: @copter
end
