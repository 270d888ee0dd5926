defmodule Dolphin.Events do
  # The catalogue: {name, fields, meaning}. The moduledoc and emit/3 both read it.
  @events [
    {:vehicle_discovered, [:vehicle, :type, :airframe],
     "a vehicle was heard for the first time (announced with its autopilot's first HEARTBEAT); `type` is `uav`, `ugv`, `usv`, `uuv` or `other`, `airframe` `copter`, `plane`, `quadplane`, `rover`, `boat`, `sub` or null (a MAV_TYPE no mission is made for: raw missions only)"},
    {:vehicle_lost, [:vehicle], "a vehicle was silent for longer than its connection timeout"},
    {:vehicle_reconnected, [:vehicle], "a lost vehicle was heard again"},
    {:station_joined, [:station, :heard], "a controller began to follow the ground station on node `station`, which hears `heard` vehicles (`Dolphin.Cluster`)"},
    {:station_left, [:station, :reason], "the ground station on node `station` left (its node went down, was cut off, or its station ended); `reason` says which"},
    {:station_changed, [:vehicle, :from, :to, :reason], "a vehicle is now reached through the ground station on node `to` instead of `from` (failover; its tasks go on)"},
    {:vehicle_conflict, [:vehicle, :stations, :reason, :other],
     "two ground stations (`stations`, node names, the followed one first) hear one id with different vehicles behind it: `vehicle` stays the chosen station's (`stations`' first), the other's is vehicle `other` here (`\"ID@NODE\"`, discovered as any vehicle is); never merged"},
    {:claim_conflict, [:vehicle, :kept, :dropped],
     "after a netsplit, both sides had claimed the vehicle (`Dolphin.Fleet.Claims`): the claim of the owner on node `kept` stays, the other's (on `dropped`) was dropped without stopping anything"},
    {:path_changed, [:vehicle, :from, :to, :reason],
     "the vehicle is now sent to on another of the links it is heard on: `from` and `to` are the links' names, `reason` is `silent` (the path in use went silent), `another_vehicle` (the path in use, taken for the vehicle's when its autopilot did not answer in time, then reported another autopilot's unique id) or `better` (the other is clearly less lossy or quicker)"},
    {:system_id_shared, [:vehicle, :path, :uid, :vehicle_uid, :other],
     "another vehicle (its autopilot's unique id `uid`) uses the system id of `vehicle` (unique id `vehicle_uid`) on the path `path`: nothing of that path is taken for `vehicle`; it is vehicle `other`'s (a vehicle of its own, named `SYSID@NETWORK`, discovered by its next heartbeat, or the one with that unique id already heard elsewhere)"},
    {:mode_changed, [:vehicle, :mode], "the vehicle reported another flight mode"},
    {:armed, [:vehicle], "the vehicle reported it is armed"},
    {:disarmed, [:vehicle], "the vehicle reported it is disarmed"},
    {:mission_item_reached, [:vehicle, :seq], "the vehicle reported mission item `seq` reached"},
    {:mission_uploaded, [:vehicle, :name, :items, :duration_ms, :retransmissions], "a mission was uploaded to a vehicle (emitted by the mission platform)"},
    {:picked, [:vehicles, :requirement], "a `pick` was served: the vehicles (a list of ids) and what was asked (text)"},
    {:pick_failed, [:requirement, :reason], "a `pick` timed out"},
    {:released, [:vehicles], "vehicles became available again"},
    {:allocated, [:run, :allocation], "the platform tasks of a run got their vehicles: `allocation` maps task ids (as strings) to vehicles"},
    {:task_started, [:run, :task_id, :parent_id, :kind, :name, :vehicle], "a task started; `vehicle` for platform tasks only (else null)"},
    {:task_progress, [:run, :task_id, :vehicle, :progress], "a platform task reported progress (an object)"},
    {:task_finished, [:run, :task_id, :parent_id, :kind, :name, :vehicle, :result, :reason], "a task ended: `result` is `done`, `stopped` or `failed`; `reason` says why (null when done)"},
    {:task_reassigned, [:run, :task_id, :from, :to, :resume_seq],
     "the platform task `task_id` failed on vehicle `from` (lost, or a failsafe) and `reassign` gave it to vehicle `to`, resuming from its item `resume_seq`"},
    {:vehicle_returned, [:run, :task_id, :vehicle, :held],
     "a lost vehicle whose task `task_id` went to another vehicle was heard again: not sent back into the task, it was made to hold (`held` true) or could not be (false)"},
    {:fence_applied, [:vehicle, :name, :fence, :rally],
     "before mission `name` flew, the vehicle was given its fence and confirmed it: `fence` the fence list's items as the autopilot keeps them (`[MAV_CMD, lat×10⁷, lon×10⁷, param1]`: a polygon's corners or a circle and its radius), `rally` its rally points (`[lat×10⁷, lon×10⁷, metres above home]`)"},
    {:separation_hold, [:vehicle, :other, :action, :distance, :height, :closest, :in_s, :limit_m, :limit_height_m],
     "the live separation monitor (`Dolphin.Separation`) holds `vehicle` (`action` `hold`), or, held and the other still coming at it, moves it out of the way (`aside`: a copter twice the vertical separation up or down): it and `other` are `distance` m apart across and `height` m in height, and would have come within the least separation (`limit_m` m across, `limit_height_m` m in height) in `in_s` s (at best `closest` m across); its mission waits, not failed"},
    {:mission_restarted, [:vehicle, :name, :reason],
     "the autopilot disarmed the vehicle before mission `name` got under way (a copter: on the ground, before its take-off), and the mission platform set it to GUIDED, armed it and started the mission again; `reason`: `disarmed_while_held` (a copter held on the ground by the separation monitor, let go since: ArduCopter disarms a copter standing armed in BRAKE) or `disarmed_before_start` (between its arming and the start)"},
    {:separation_clear, [:vehicle, :other, :distance, :held_ms],
     "the way is clear: held `vehicle` goes on with its mission after `held_ms` clock ms; `other` (the vehicle it was held for) is `distance` m away across (null: no longer in the air)"},
    {:condition_met, [:run, :task_id, :condition, :branch],
     "the condition of an until, wait_for, condition, one_of or all_of held; `condition` is its source text, `branch` the index in one_of/all_of (else null)"},
    {:sensor_declared, [:sensor, :source, :unit, :scale, :offset, :stale_after],
     "a script declared a sensor (`sensor :smoke, from: ...`): every vehicle now reports its readings of `source` (`NAMED_VALUE SMOKE`, `SCALED_PRESSURE2.temperature`); its value is raw × `scale` + `offset`, in `unit`; a reading older than `stale_after` ms (null: never) is unknown"},
    {:sensor_threshold, [:run, :task_id, :vehicle, :sensor, :value, :unit, :lat, :lon, :h, :condition, :sent],
     "a sensor reading met what a script waited for: a condition that reads it held (`condition` its text), or `on_sensor` detected it; `vehicle` read `value` at `lat`, `lon`, `h` (where it was; null while unknown); `sent` the vehicle `on_sensor` sent to look (else null)"},
    {:message, [:text], "a script's `message`"},
    {:signal_posted, [:key, :value], "a script's `post`"},
    {:signal_consumed, [:key, :value], "a successful `consume`"},
    {:script_started, [:script], "a script began to run"},
    {:script_finished, [:script, :result, :reason], "a script ended: `result` is `done`, `stopped`, `halted` or `failed`; `reason` says why"}
  ]

  @moduledoc """
  The one catalogue of Dolphin's events: what happens to vehicles, picks, tasks
  and scripts, as plain maps published on `Dolphin.PubSub` topic `:events`.

      Dolphin.Events.subscribe()
      # {:dolphin, :events, %{event: :task_started, at_ms: 81_234, task_id: 3, ...}}

  Every event is a map with `:event` (its name), `:at_ms` (the clock time of
  the process that emitted it: `Dolphin.Clock.now_ms/0`, or a run's own time
  source) and exactly the fields listed below. `emit/3` refuses a name that is
  not in the catalogue or fields that differ from it.

  `mix dolphin.run --events FILE` writes them one JSON object per line with
  `Dolphin.Events.Writer`: `{"t_ms": ..., "event": NAME, ...fields}`, where
  `t_ms` is clock milliseconds since the writer started. In JSON, vehicles are
  system ids (integers), names and atoms are strings, absent values `null`.

  #{Enum.map_join(@events, "\n  ", fn {name, fields, doc} -> "* `#{name}` (#{Enum.join(fields, ", ")}) — #{doc}" end)}

  Kinds of task (`kind`): `idle`, `action`, `condition`, `sequence`,
  `concurrent`, `until`, `during`, `wait_for`, `one_of`, `all_of`, `watch`,
  `on_sensor`, and
  for platform tasks the platform's kind (`mission`, `test`, ...).
  """

  alias Dolphin.PubSub

  @catalogue Map.new(@events, fn {name, fields, _} -> {name, fields} end)

  @type name :: atom()
  @type event :: %{required(:event) => name(), required(:at_ms) => integer(), optional(atom()) => term()}

  @doc "The catalogue: event names and their fields."
  @spec catalogue() :: %{name() => [atom()]}
  def catalogue, do: @catalogue

  @doc """
  Publishes an event. `fields` must be exactly the event's fields (a map or
  keyword list); `at_ms` defaults to `Dolphin.Clock.now_ms/0`.
  """
  @spec emit(name(), map() | keyword(), integer()) :: :ok
  def emit(name, fields, at_ms \\ Dolphin.Clock.now_ms()) do
    fields = Map.new(fields)

    case Map.fetch(@catalogue, name) do
      {:ok, keys} ->
        # (Every field named and no other: without sorting, which a burst of
        # events from a thousand tasks at once feels.)
        if map_size(fields) != length(keys) or not Enum.all?(keys, &is_map_key(fields, &1)),
          do: raise(ArgumentError, "event #{inspect(name)} has fields #{inspect(keys)}, got: #{inspect(Map.keys(fields))}")

      :error ->
        raise ArgumentError, "unknown event #{inspect(name)}; the catalogue has #{inspect(Map.keys(@catalogue))}"
    end

    PubSub.publish(:events, Map.merge(fields, %{event: name, at_ms: at_ms}))
  end

  @doc "Subscribes the caller to every event: `{:dolphin, :events, event}` messages."
  @spec subscribe() :: :ok
  def subscribe, do: PubSub.subscribe(:events)

  @doc "Unsubscribes the caller."
  @spec unsubscribe() :: :ok
  def unsubscribe, do: PubSub.unsubscribe(:events)

  @doc """
  One event as a JSON line (no newline), `t_ms` counted from `origin_ms`.

      iex> Dolphin.Events.to_json(%{event: :armed, at_ms: 1500, vehicle: 2}, 1000)
      ~s({"t_ms":500,"event":"armed","vehicle":2})
  """
  @spec to_json(event(), integer()) :: String.t()
  def to_json(%{event: name, at_ms: at} = event, origin_ms) do
    fields = event |> Map.drop([:event, :at_ms]) |> Enum.sort() |> Enum.map(fn {k, v} -> {Atom.to_string(k), json(v)} end)
    IO.iodata_to_binary(:jiffy.encode({[{"t_ms", at - origin_ms}, {"event", Atom.to_string(name)} | fields]}))
  end

  defp json(nil), do: :null
  defp json(v) when is_boolean(v) or is_number(v), do: v
  defp json(v) when is_atom(v), do: Atom.to_string(v)
  defp json(v) when is_binary(v), do: if(String.valid?(v), do: v, else: inspect(v))
  defp json(%Dolphin.Geo.Location{lat: lat, lon: lon, h: h}), do: {[{"lat", lat}, {"lon", lon}, {"h", h}]}
  defp json(%Dolphin.Fleet.VehicleSet{ids: ids}), do: ids
  defp json(%_{} = v), do: inspect(v)
  defp json(v) when is_list(v), do: if(Keyword.keyword?(v) and v != [], do: json(Map.new(v)), else: Enum.map(v, &json/1))
  defp json(v) when is_tuple(v), do: v |> Tuple.to_list() |> Enum.map(&json/1)
  defp json(v) when is_map(v), do: {Enum.map(Enum.sort(v), fn {k, x} -> {key(k), json(x)} end)}
  defp json(v), do: inspect(v)

  defp key(k) when is_binary(k), do: k
  defp key(k) when is_atom(k), do: Atom.to_string(k)
  defp key(k), do: inspect(k)
end
