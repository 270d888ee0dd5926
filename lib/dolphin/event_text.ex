defmodule Dolphin.EventText do
  @moduledoc """
  What an operator reads of a run, in one place: one line per event, and
  which events a run's log shows. `mix dolphin.run` and the console
  (`Dolphin.Console.events/1`) both print events through `event_line/2`, so an
  event reads the same wherever it is shown.

      iex> Dolphin.EventText.event_text(%{event: :armed, vehicle: 2})
      "vehicle 2 armed"
      iex> Dolphin.EventText.event_line(%{event: :task_finished, task_id: 5, kind: :test, name: "survey", vehicle: 1, result: :done, reason: nil, at_ms: 31_300}, 500)
      ~s([   30.8 s] task 5 test "survey" on vehicle 1: done)

  The rest of the command line's view lives beside it:

    * `Dolphin.CLI.Run` — a compiled script run as `mix dolphin.run` runs it:
      vehicles started, the live output, the script, the summary, teardown;
    * `Dolphin.CLI.Renderer` — the process that prints the events of a run
      (and on a terminal redraws the status block below them);
    * `Dolphin.CLI.StatusBlock` — the status block's text, one line per vehicle;
    * `Dolphin.CLI.Signals` — SIGINT and SIGTERM as messages;
    * `Dolphin.CLI.Values` — every task's options, checked; and the one
      error of a command line, `Dolphin.CommandLineError`: one that cannot
      be run (exit status 2), or a run that could not start (1).
  """

  alias Dolphin.Console.Format
  alias Dolphin.Fleet.VehicleSet

  # Events a run's log shows besides the script's messages (for an operator's
  # eye: the rest is in --events and the console's events/1).
  @logged [
    :vehicle_discovered,
    :vehicle_lost,
    :vehicle_reconnected,
    :station_joined,
    :station_left,
    :station_changed,
    :vehicle_conflict,
    :claim_conflict,
    :path_changed,
    :system_id_shared,
    :picked,
    :released,
    :pick_failed,
    :mode_changed,
    :armed,
    :disarmed,
    :mission_uploaded,
    :fence_applied,
    :mission_item_reached,
    :condition_met,
    :task_reassigned,
    :vehicle_returned,
    :separation_hold,
    :separation_clear,
    :mission_restarted,
    :sensor_declared,
    :sensor_threshold
  ]

  @doc """
  One event (`Dolphin.Events`) as a line stamped with its clock time since
  `origin_ms`.
  """
  @spec event_line(map(), integer()) :: String.t()
  def event_line(%{at_ms: at} = event, origin_ms), do: stamp(at, origin_ms, event_text(event))

  @doc """
  A line of the log at clock time `at_ms`, with the time since `origin_ms` in front.

      iex> Dolphin.EventText.stamp(81_200, 0, "vehicle 1 armed")
      "[   81.2 s] vehicle 1 armed"
  """
  @spec stamp(integer(), integer(), String.t()) :: String.t()
  def stamp(at_ms, origin_ms, text), do: "[#{String.pad_leading(Format.seconds(at_ms - origin_ms), 9)}] " <> text

  @doc """
  Whether a run's log shows `event`: the script's messages always; with
  `quiet` nothing else; otherwise the vehicles' comings and goings, picks,
  modes, arming, missions, conditions, and the platform tasks (those on a
  vehicle) as they start and end, with every failure.

      iex> Dolphin.EventText.logged?(%{event: :message, text: "hi"}, true)
      true
      iex> Dolphin.EventText.logged?(%{event: :armed, vehicle: 1}, true)
      false
      iex> Dolphin.EventText.logged?(%{event: :task_started, task_id: 2, kind: :sequence, name: nil, vehicle: nil}, false)
      false
  """
  @spec logged?(map(), boolean()) :: boolean()
  def logged?(%{event: :message}, _quiet), do: true
  def logged?(_event, true), do: false
  def logged?(%{event: name}, _quiet) when name in @logged, do: true
  def logged?(%{event: :task_started} = e, _quiet), do: Map.get(e, :vehicle) != nil
  def logged?(%{event: :task_finished, result: :failed}, _quiet), do: true
  def logged?(%{event: :task_finished} = e, _quiet), do: Map.get(e, :vehicle) != nil
  def logged?(_event, _quiet), do: false

  @doc """
  One event in words: the only text of each event, for the run's log and the
  console alike. An event with no words of its own is shown as its fields.
  """
  @spec event_text(map()) :: String.t()
  def event_text(%{event: :message, text: text}), do: "message: #{text}"
  def event_text(%{event: :vehicle_discovered} = e), do: "vehicle #{e.vehicle} discovered (#{Dolphin.Vehicles.View.describe_kind(%Dolphin.Vehicles.View{type: e.type, airframe: e[:airframe]})})"
  def event_text(%{event: :vehicle_lost} = e), do: "vehicle #{e.vehicle} lost"
  def event_text(%{event: :vehicle_reconnected} = e), do: "vehicle #{e.vehicle} reconnected"
  def event_text(%{event: :station_joined} = e), do: "ground station #{e.station} joined (#{e.heard} vehicle(s))"
  def event_text(%{event: :station_left} = e), do: "ground station #{e.station} left: #{e.reason}"
  def event_text(%{event: :station_changed} = e), do: "vehicle #{e.vehicle} now through #{e.to} (was #{e.from}: #{e.reason})"

  def event_text(%{event: :claim_conflict} = e),
    do: "vehicle #{e.vehicle} was claimed on both sides of a netsplit: #{e.kept}'s claim kept, #{e.dropped}'s dropped"

  def event_text(%{event: :vehicle_conflict} = e),
    do: "vehicle #{e.vehicle}: #{Enum.join(e.stations, " and ")} hear two different vehicles (#{e.reason}); the one #{List.last(e.stations)} hears is vehicle #{e.other} here"

  def event_text(%{event: :path_changed} = e),
    do: "vehicle #{e.vehicle}: now through #{e.to} (#{path_reason(e.reason, e.from)})"

  def event_text(%{event: :system_id_shared} = e),
    do: "vehicle #{e.vehicle}: another vehicle with its system id is heard on #{e.path} (unique id #{e.uid}, not #{e.vehicle_uid}): that is vehicle #{e.other}"

  def event_text(%{event: :mode_changed} = e), do: "vehicle #{e.vehicle} mode #{Format.mode(e.mode)}"
  def event_text(%{event: :armed} = e), do: "vehicle #{e.vehicle} armed"
  def event_text(%{event: :disarmed} = e), do: "vehicle #{e.vehicle} disarmed"
  def event_text(%{event: :mission_item_reached} = e), do: "vehicle #{e.vehicle} reached item #{e.seq}"

  def event_text(%{event: :mission_uploaded} = e),
    do: "vehicle #{e.vehicle}: mission #{inspect(e.name)} uploaded (#{e.items} items, #{e.duration_ms} ms, #{e.retransmissions} retransmissions)"

  def event_text(%{event: :picked} = e), do: "picked #{VehicleSet.format(e.vehicles)} (#{e.requirement})"
  def event_text(%{event: :pick_failed} = e), do: "pick failed: #{e.reason}"
  def event_text(%{event: :released} = e), do: "released #{VehicleSet.format(e.vehicles)}"
  def event_text(%{event: :allocated} = e), do: "run #{e.run}: " <> Enum.map_join(Enum.sort(e.allocation), ", ", fn {t, v} -> "task #{t} on vehicle #{v}" end)

  def event_text(%{event: :task_started} = e), do: "task #{e.task_id} #{e.kind} #{inspect(cut(e.name, 60))} started" <> on_vehicle(e)

  def event_text(%{event: :task_progress} = e), do: "task #{e.task_id} on vehicle #{e.vehicle}: " <> Format.task_state(nil, e)

  # "stopped (the run's time (--for) is over)": the result is not said twice.
  def event_text(%{event: :task_finished} = e),
    do: "task #{e.task_id} #{e.kind} #{inspect(cut(e.name, 60))}#{on_vehicle(e)}: #{e.result}" <> because(e.reason)

  def event_text(%{event: :fence_applied} = e),
    do: "vehicle #{e.vehicle}: fence of #{inspect(e.name)} on (#{zones(e.fence)}, #{length(e.rally)} rally point(s))"

  def event_text(%{event: :separation_hold, action: action} = e) when action in [:aside, "aside"],
    do: "vehicle #{e.vehicle} moves out of vehicle #{e.other}'s way: #{e.distance} m away (#{e.height} m in height), coming within the least separation in #{e.in_s} s"

  def event_text(%{event: :separation_hold} = e),
    do: "vehicle #{e.vehicle} holds: vehicle #{e.other} is #{e.distance} m away (#{e.height} m in height) and would come within the least separation in #{e.in_s} s"

  def event_text(%{event: :separation_clear} = e),
    do: "vehicle #{e.vehicle} goes on after #{Format.seconds(e.held_ms)} held" <> if(e.distance, do: " (vehicle #{e.other} #{e.distance} m away)", else: "")

  def event_text(%{event: :mission_restarted} = e) do
    why =
      case to_string(e.reason) do
        "disarmed_while_held" -> "the autopilot disarmed it on the ground while it was held"
        _ -> "the autopilot disarmed it before the mission got under way"
      end

    "vehicle #{e.vehicle}: #{inspect(e.name)} armed and started again (#{why})"
  end

  def event_text(%{event: :sensor_declared} = e),
    do: "sensor #{e.sensor}: #{e.source}" <> if(e.unit, do: " in #{e.unit}", else: "") <> if(e.stale_after, do: ", unknown #{Format.seconds(e.stale_after)} after its last reading", else: "")

  def event_text(%{event: :sensor_threshold} = e) do
    where = if e.lat, do: " at #{Float.round(e.lat * 1.0, 6)}, #{Float.round(e.lon * 1.0, 6)} (#{round(e.h)} m)", else: " (position unknown)"
    unit = if e.unit, do: " #{e.unit}", else: ""
    sent = if Map.get(e, :sent), do: ": vehicle #{e.sent} goes to look", else: ""
    "vehicle #{e.vehicle} read #{e.sensor} #{e.value}#{unit}#{where} (#{e.condition})#{sent}"
  end

  def event_text(%{event: :task_reassigned} = e), do: "task #{e.task_id}: vehicle #{e.from} failed it; vehicle #{e.to} takes it over from item #{e.resume_seq}"

  def event_text(%{event: :vehicle_returned} = e),
    do: "vehicle #{e.vehicle} is back, its task #{e.task_id} taken over: " <> if(e.held, do: "holding", else: "could not be made to hold")

  def event_text(%{event: :condition_met} = e),
    do: "task #{e.task_id}: #{e.condition} holds" <> if(Map.get(e, :branch), do: " (branch #{e.branch})", else: "")

  def event_text(%{event: :signal_posted} = e), do: "signal #{inspect(e.key)} posted: #{inspect(e.value, charlists: :as_lists)}"
  def event_text(%{event: :signal_consumed} = e), do: "signal #{inspect(e.key)} consumed: #{inspect(e.value, charlists: :as_lists)}"
  def event_text(%{event: :script_started} = e), do: "script #{e.script} started"
  def event_text(%{event: :script_finished} = e), do: "script #{e.script}: #{e.result}" <> because(e.reason)
  def event_text(%{event: name} = e), do: "#{name} " <> inspect(Map.drop(e, [:event, :at_ms]), charlists: :as_lists)

  defp on_vehicle(e), do: if(v = Map.get(e, :vehicle), do: " on vehicle #{v}", else: "")

  defp because(nil), do: ""
  defp because(reason), do: " (#{String.replace_prefix(reason, "stopped: ", "")})"

  # A fence list's zones: a polygon is a run of corner items (each says how many), a circle one item.
  defp zones(items) do
    n = items |> Enum.map(fn [command, _, _, param1] -> if command in [5001, 5002], do: 1 / max(param1, 1), else: 1 end) |> Enum.sum() |> round()
    "#{n} zone(s)"
  end

  defp cut(nil, _n), do: ""
  defp cut(text, n), do: if(String.length(text) > n, do: String.slice(text, 0, n - 1) <> "…", else: text)

  defp path_reason(reason, from) when reason in [:silent, "silent"], do: "#{from} went silent"
  defp path_reason(reason, from) when reason in [:another_vehicle, "another_vehicle"], do: "#{from} is another vehicle's"
  defp path_reason(_better, from), do: "better than #{from}"
end
