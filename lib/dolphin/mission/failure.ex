defmodule Dolphin.Mission.Failure do
  @moduledoc """
  Why a mission could not be flown, or resumed on another vehicle, as data:
  the engine carries it as the task's failure reason
  (`Dolphin.Engine.Failure`), `reassign` reads `vehicle_fault?` from it
  (`Dolphin.Mission.Platform.vehicle_fault?/1`), and `message/1` words it,
  once, for every place that shows it (the run's log, `--events`, the
  console, the flight report).

  Fields: `mission` (its name), `vehicle`, `step` (where it failed: the
  executor's steps `:hold`, `:clear`, `:upload`, `:verify`, `:guided`,
  `:arm`, `:start`, `:flying`, or `:resume` when taking it over on another
  vehicle), `cause` (below), `status_texts` (what the vehicle said about it,
  its STATUSTEXTs since the mission started, `{severity, text}`, of which
  the first warning or worse is quoted) and `vehicle_fault?` (the
  vehicle caused it — a failsafe, a refused arm —, so that another vehicle
  may take the mission over).

  Causes:

    * `{:cannot_make_items, text}` — the mission cannot be turned into items;
    * `{:booting, :uninit | :boot, seconds}` — the vehicle was still booting;
    * `:not_connected` — the vehicle is not heard;
    * `:fake_vehicle` — a fake vehicle (`--fake`) given a MAVLink mission;
    * `:no_take_off` — on the ground, and the mission does not take off;
    * `{:exchange_crashed, exit_reason}` — a step's exchange crashed;
    * `{:refused, exception}` — the vehicle refused or did not answer a
      step (`Dolphin.CommandError`, `Dolphin.MissionError`,
      `Dolphin.ManoeuvreError`);
    * `{:read_back_differs, %Dolphin.Mission.MismatchError{}}`;
    * `{:read_back_failed, exception, attempts}`;
    * `{:grounded, seconds, item}` — armed on the ground, not climbing
      (`item`: `{seq, total, name, take_off?}` of the current item, or nil);
    * `{:stuck, seconds, {seq, total, name, metres}}` — it stood still in
      AUTO, `metres` short of waypoint `seq`, for `seconds` of clock time
      (ArduRover stops short of its fence and says nothing);
    * `{:left_auto, mode}` — the vehicle left AUTO (a failsafe, the pilot);
    * `:disarmed` — it disarmed before the mission ended;
    * `{:disarmed_before_take_off, times}` — armed for its take-off, it
      disarmed on the ground before the flight began, `times` times (it was
      armed and started again after each but the last);
    * `{:disarmed_before_start, times}` — the same for a rover, boat or
      submarine: armed for its mission, it disarmed before it began;
    * `{:landed_early, current, total}` — it landed and disarmed before the end;
    * `:has_jumps`, `:nothing_but_take_off`, `{:nothing_left, reached}`,
      `{:home_unknown, vehicle}`, `{:position_unknown, vehicle}`,
      `{:cannot_resume, text}` — it cannot be resumed on another vehicle.

      iex> f = %Dolphin.Mission.Failure{mission: "Survey", vehicle: 2, step: :flying, cause: {:left_auto, "RTL"}, vehicle_fault?: true}
      iex> Exception.message(f)
      "the vehicle left AUTO for RTL before the mission ended"
  """

  defexception mission: nil, vehicle: nil, step: nil, cause: nil, status_texts: [], vehicle_fault?: false

  @type step :: :hold | :clear | :upload | :verify | :fence | :guided | :arm | :start | :flying | :resume
  @type cause ::
          {:cannot_make_items, String.t()}
          | {:booting, :uninit | :boot, non_neg_integer()}
          | :not_connected
          | :fake_vehicle
          | :no_take_off
          | {:exchange_crashed, term()}
          | {:refused, Exception.t()}
          | {:read_back_differs, Exception.t()}
          | {:read_back_failed, Exception.t(), pos_integer()}
          | {:grounded, non_neg_integer(), {non_neg_integer(), non_neg_integer(), String.t(), boolean()} | nil}
          | {:stuck, non_neg_integer(), {non_neg_integer(), non_neg_integer(), String.t(), non_neg_integer()}}
          | {:left_auto, String.t()}
          | :disarmed
          | {:disarmed_before_take_off, pos_integer()}
          | {:disarmed_before_start, pos_integer()}
          | {:landed_early, term(), term()}
          | :has_jumps
          | {:cannot_resume, String.t()}
          | :nothing_but_take_off
          | {:nothing_left, non_neg_integer()}
          | {:home_unknown, term()}
          | {:position_unknown, term()}

  @type t :: %__MODULE__{
          mission: String.t() | nil,
          vehicle: term(),
          step: step() | nil,
          cause: cause(),
          status_texts: [{integer(), String.t()}],
          vehicle_fault?: boolean()
        }

  @impl true
  # What made a vehicle leave AUTO is often only a notice ("Polygon fence
  # breached", severity 5): said too; otherwise the first warning or worse.
  def message(%__MODULE__{cause: {:left_auto, _}} = f) do
    case Enum.find(f.status_texts, fn {severity, _} -> severity <= 5 end) do
      {_, text} -> words(f) <> ": the autopilot says \"#{text}\""
      nil -> words(f)
    end
  end

  def message(%__MODULE__{} = f), do: words(f) <> Dolphin.ManoeuvreError.says(f.status_texts, [])

  defp words(%{cause: {:cannot_make_items, text}} = f), do: "mission #{inspect(f.mission)} cannot be turned into items: #{text}"

  defp words(%{cause: {:booting, status, seconds}} = f),
    do: "vehicle #{f.vehicle} was still booting after #{seconds} s (MAV_STATE #{status |> Atom.to_string() |> String.upcase()})"

  defp words(%{cause: :not_connected} = f), do: "vehicle #{f.vehicle} is not connected"

  defp words(%{cause: :fake_vehicle} = f),
    do: "mission #{inspect(f.mission)} needs a MAVLink vehicle; vehicle #{f.vehicle} is a fake vehicle (--fake), which runs only fake-platform tasks"

  defp words(%{cause: :no_take_off} = f), do: "vehicle #{f.vehicle} is on the ground and the mission has no take-off"
  defp words(%{cause: {:exchange_crashed, reason}} = f), do: "#{f.step} crashed: #{Exception.format_exit(reason)}"
  defp words(%{cause: {:refused, e}}), do: Exception.message(e)
  defp words(%{cause: {:read_back_differs, e}}), do: "the mission read back differs from the one uploaded: #{Exception.message(e)}"

  defp words(%{cause: {:read_back_failed, e, attempts}}),
    do: "reading the mission back to verify it failed#{if attempts > 1, do: " (#{attempts} attempts)"}: #{Exception.message(e)}"

  defp words(%{cause: {:stuck, seconds, {seq, last, name, metres}}} = f),
    do:
      "vehicle #{f.vehicle} has stood still for #{seconds} s of the mission, #{metres} m short of item #{seq} of #{last} (#{name}), in AUTO: " <>
        "something stops it there (an obstacle, or its fence: a rover stops short of it)"

  defp words(%{cause: {:grounded, seconds, item}} = f) do
    {at, waiting} =
      case item do
        {seq, last, name, take_off?} -> {" (at item #{seq} of #{last}, #{name})", if(take_off?, do: "its take-off does not climb", else: "the mission does not go on")}
        nil -> {"", "the mission does not go on"}
      end

    "vehicle #{f.vehicle} has been armed on the ground for #{seconds} s of the mission#{at}: #{waiting}"
  end

  defp words(%{cause: {:left_auto, mode}}), do: "the vehicle left AUTO for #{mode} before the mission ended"
  defp words(%{cause: :disarmed}), do: "the vehicle disarmed before the mission ended"

  defp words(%{cause: {:disarmed_before_take_off, times}} = f),
    do:
      "vehicle #{f.vehicle} disarmed on the ground before its take-off, #{times} time(s) (a copter armed without taking off disarms itself after DISARM_DELAY: the mission's start reached it too late each time)"

  defp words(%{cause: {:disarmed_before_start, times}} = f),
    do: "vehicle #{f.vehicle} disarmed before its mission began, #{times} time(s) (it was armed and the mission started again after each but the last)"

  defp words(%{cause: {:landed_early, current, total}}), do: "the vehicle landed and disarmed before the mission's end (at item #{current} of #{total})"
  defp words(%{cause: {:cannot_resume, text}} = f), do: "mission #{inspect(f.mission)} cannot be resumed: #{text}"
  defp words(%{cause: :has_jumps} = f), do: "mission #{inspect(f.mission)} has jumps (DO_JUMP): it cannot be resumed on another vehicle"
  defp words(%{cause: :nothing_but_take_off} = f), do: "mission #{inspect(f.mission)} has nothing to fly but its take-off"
  defp words(%{cause: {:nothing_left, reached}} = f), do: "mission #{inspect(f.mission)} has nothing left to fly after item #{reached}"
  defp words(%{cause: {:home_unknown, from}}), do: "the home of vehicle #{from}, which its items were made from, is not known"
  defp words(%{cause: {:position_unknown, vehicle}}), do: "the position of vehicle #{vehicle} is not known"
end
