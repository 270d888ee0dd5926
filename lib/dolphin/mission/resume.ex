defmodule Dolphin.Mission.Resume do
  @moduledoc """
  A mission taken over by another vehicle: what is left of it, as a mission
  of its own (used when `reassign` gives the mission of a lost vehicle to
  another one; see `Dolphin.Engine.Watch`).

  The vehicle that flew it reported the last item it reached (`reached`, a
  seq of the mission's items, or nil). The new vehicle goes on from the first
  item not reached:

    * it takes off where it stands, to the height of the mission's take-off
      (or, without one, of the first item left);
    * then it flies the items from `resume_seq` on, as they were: the first
      navigation item after the one reached (a take-off excepted). The
      commands in between (camera, speed) ran as the first vehicle left the
      item it reached: photos are not taken again. With nothing reached,
      everything after the mission's take-off is flown;
    * a survey pass half flown is flown again whole: when the first item
      left ends a pass of `survey_area`, the new vehicle starts at that
      pass's beginning. A survey thus goes on with the passes not flown.

  Item `seq` of the mission becomes item `seq - resume_seq + 2` of the
  resumed one (item 0 is home, item 1 the take-off): `original_seq/2` maps
  back.

      iex> alias Dolphin.Mission
      iex> alias Dolphin.Mission.Command, as: C
      iex> home = Dolphin.Geo.location(40.444233, -7.375234, 820)
      iex> m = Mission.new("Survey", [C.home(home), C.take_off(Dolphin.Geo.location(40.444233, -7.375234, 850)), C.survey_area(100, 90, 30)])
      iex> # Item 1: the take-off; 2..7: three passes (2-3, 4-5, 6-7). Reached 4: the
      iex> # second pass begun, not flown: it is flown again from 4.
      iex> {:ok, resumed, 4} = Dolphin.Mission.Resume.resume(m, 4, Dolphin.Geo.location(40.4443, -7.3753, 820))
      iex> # Home, the take-off, then items 4..7.
      iex> Mission.item_count(resumed)
      6
  """

  alias Dolphin.Geo.Location
  alias Dolphin.Mission
  alias Dolphin.Mission.{Command, Items}

  @takeoff 22

  @doc """
  The resumed mission for a vehicle standing at `at`, and the seq of the
  first item it flies: `{:ok, mission, resume_seq}`, or `{:error, why}` when
  the mission cannot be resumed (it jumps, or nothing is left to fly): a
  `Dolphin.Mission.Failure` of step `:resume`.
  `mission` must have its home (the first vehicle's home, when it had none).
  """
  @spec resume(Mission.t(), non_neg_integer() | nil, Location.t()) :: {:ok, Mission.t(), pos_integer()} | {:error, Dolphin.Mission.Failure.t()}
  def resume(%Mission{} = mission, reached, %Location{} = at) do
    items = Mission.to_items(mission)

    with :ok <- no_jumps(mission, items),
         {:ok, seq} <- resume_seq(mission, items, reached) do
      left = Enum.filter(items, &(&1.seq >= seq))
      takeoff = Enum.find(items, &(&1.command == @takeoff)) || Enum.find(left, &positioned?/1)
      height = if takeoff, do: takeoff.z, else: at.h
      up = Command.take_off(Location.new(at.lat, at.lon, height))
      {:ok, %Mission{name: mission.name, home: nil, commands: [up | Enum.map(left, &as_command/1)]}, seq}
    end
  rescue
    e in ArgumentError -> {:error, cannot(mission, {:cannot_resume, Exception.message(e)})}
  end

  @doc "The seq, in the original mission, of item `seq` of a mission resumed from `resume_seq` (nil for home and the take-off)."
  @spec original_seq(non_neg_integer(), pos_integer()) :: pos_integer() | nil
  def original_seq(seq, _resume_seq) when seq < 2, do: nil
  def original_seq(seq, resume_seq), do: seq - 2 + resume_seq

  defp cannot(mission, cause), do: %Dolphin.Mission.Failure{mission: mission.name, step: :resume, cause: cause}

  defp no_jumps(mission, items) do
    jump = Items.command_number(:mav_cmd_do_jump)

    if Enum.any?(items, &(&1.command == jump)),
      do: {:error, cannot(mission, :has_jumps)},
      else: :ok
  end

  # Nothing reached: the take-off was not even done, nor what follows it.
  defp resume_seq(mission, items, nil) do
    case Enum.find(items, &(&1.seq > 0 and &1.command != @takeoff)) do
      nil -> {:error, cannot(mission, :nothing_but_take_off)}
      %{seq: seq} -> {:ok, seq}
    end
  end

  defp resume_seq(mission, items, reached) do
    case Enum.find(items, &(&1.seq > reached and navigation?(&1) and &1.command != @takeoff)) do
      nil ->
        {:error, cannot(mission, {:nothing_left, reached})}

      %{seq: seq} ->
        # A survey's pass is two items: a pass whose end is next was not flown whole.
        pass_end? =
          Enum.any?(Items.spans(mission), fn {kind, first, count} ->
            kind == :survey_area and seq > first and seq < first + count and rem(seq - first, 2) == 1
          end)

        {:ok, if(pass_end?, do: seq - 1, else: seq)}
    end
  end

  # Navigation items: MAV_CMD up to 95, as ArduPilot counts them (Dolphin.Mission.ending/1).
  defp navigation?(item), do: item.seq > 0 and item.command <= 95
  defp positioned?(item), do: item.frame != Items.frames().mission

  defp as_command(item) do
    Command.item(item.command,
      frame: item.frame,
      x: item.x,
      y: item.y,
      z: item.z,
      params: [item.param1, item.param2, item.param3, item.param4],
      autocontinue: item.autocontinue
    )
  end
end
