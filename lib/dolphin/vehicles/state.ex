defmodule Dolphin.Vehicles.State do
  @moduledoc """
  What the ground station knows of one vehicle, kept by a pure function:
  `apply(state, frame, now_ms)` folds one received frame into the state.

  | field | from | meaning |
  | --- | --- | --- |
  | `type`, `autopilot` | HEARTBEAT (autopilot component) | `MAV_TYPE` number; `:ardupilot`, `:px4` or `:other` |
  | `mode` | HEARTBEAT | mode name (`:guided`, `:auto`, ... see `Dolphin.Vehicles.Modes`) or `{:custom, n}` |
  | `armed`, `system_status` | HEARTBEAT | `base_mode` bit 128; `MAV_STATE` number |
  | `position` | GLOBAL_POSITION_INT | `%{lat, lon, alt, relative_alt, heading, velocity}`: degrees, metres, degrees (nil when unknown), `{north, east, up}` m/s |
  | `home` | HOME_POSITION | `%{lat, lon, alt}` |
  | `battery` | SYS_STATUS, BATTERY_STATUS (id 0) | remaining fraction 0.0..1.0, `nil` until reported |
  | `mission` | MISSION_CURRENT, MISSION_ITEM_REACHED | `%{current, total, state, reached}` of the mission on the vehicle: all `nil` again when a new one is uploaded or it is cleared (`mission_replaced/1`) |
  | `landed` | EXTENDED_SYS_STATE | `:on_ground`, `:in_air`, `:takeoff`, `:landing` or nil |
  | `status_texts` | STATUSTEXT | the last 20 `{severity, text}`, newest first |
  | `sensors` | NAMED_VALUE_FLOAT/INT, any message field watched (any component) | the readings of the sources in `watch` (`Dolphin.Sensors.Readings`), by source |
  | `uid` | AUTOPILOT_VERSION (autopilot component) | the autopilot's unique id (`unique_id/1`; 0: it has none), `nil` until reported |
  | `components` | HEARTBEAT of other components | e.g. `:camera`, `:gimbal` |
  | `link` | every frame | `%{received, lost, last_seen_ms}`: `lost` counts sequence gaps |
  | `link_quality` | TIMESYNC answers, sequence gaps | a `Dolphin.Vehicles.LinkQuality`: round trip and loss both ways (`link_figures/1`) |
  | `boot` | GLOBAL_POSITION_INT (autopilot component) | `{time_boot_ms, monotonic µs}`: the autopilot's clock and ours as it came, `nil` until heard |
  """

  import Bitwise

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.Frame
  alias Dolphin.Sensors.Readings
  alias Dolphin.Vehicles.{LinkQuality, Modes}

  @max_texts 20
  @camera_type 30
  @gimbal_type 26
  @camera_compids 100..105

  defstruct id: nil,
            type: nil,
            autopilot: nil,
            mode: nil,
            armed: false,
            system_status: nil,
            position: nil,
            home: nil,
            battery: nil,
            mission: %{current: nil, total: nil, state: nil, reached: nil},
            landed: nil,
            status_texts: [],
            uid: nil,
            sensors: %{},
            watch: %{named: %{}, messages: %{}, keep: %{}},
            components: MapSet.new(),
            link: %{received: 0, lost: 0, last_seen_ms: nil},
            link_quality: LinkQuality.new(),
            autopilot_compid: nil,
            seqs: %{},
            boot: nil

  @type t :: %__MODULE__{}

  @doc "The state of a vehicle not heard from yet."
  @spec new(Dolphin.Vehicles.Id.t()) :: t()
  def new(id), do: %__MODULE__{id: id}

  @doc "Folds one frame from the vehicle into its state."
  @spec apply(t(), Frame.t(), integer()) :: t()
  def apply(%__MODULE__{} = state, %Frame{} = frame, now_ms) do
    state
    |> count(frame, now_ms)
    |> message(frame.compid, frame.message)
    |> sense(frame, now_ms)
  end

  @doc "The state watching the sensor sources of `watch` (`Dolphin.Sensors.Readings.watch/1`); readings of sources no longer watched are dropped."
  @spec watch_sensors(t(), Readings.watch()) :: t()
  def watch_sensors(%__MODULE__{} = state, watch), do: %{state | watch: watch, sensors: Map.take(state.sensors, Map.keys(watch.keep))}

  # Nothing watched (no script declared a sensor): nothing to look at.
  defp sense(%{watch: %{named: named, messages: messages}} = state, _frame, _now) when map_size(named) == 0 and map_size(messages) == 0, do: state

  defp sense(state, frame, now) do
    case Readings.fold(state.sensors, state.watch, frame.compid, frame.message, now, fn -> location(state.position) end) do
      same when same === state.sensors -> state
      sensors -> %{state | sensors: sensors}
    end
  end

  defp location(nil), do: nil
  defp location(p), do: Dolphin.Geo.Location.new(p.lat, p.lon, p.alt)

  # The autopilot's own clock against ours: {its time_boot_ms, our monotonic
  # µs when it came} (Dolphin.SITL.Pace measures a simulated vehicle's pace
  # with it). Not in the view: it changes with every frame.
  defp boot_clock(%{autopilot_compid: compid} = state, from, time_boot_ms) when from == compid or (compid == nil and from == 1),
    do: %{state | boot: {time_boot_ms, System.monotonic_time(:microsecond)}}

  defp boot_clock(state, _from, _time_boot_ms), do: state

  # Sequence numbers are per component; a gap is frames lost on the way.
  defp count(%{link: link, seqs: seqs} = state, %Frame{compid: compid, seq: seq}, now_ms) do
    lost =
      case Map.fetch(seqs, compid) do
        {:ok, last} -> rem(seq - last - 1 + 256, 256)
        :error -> 0
      end

    # A jump of more than half the sequence space is a restart or a reordering, not a loss.
    lost = if lost > 128, do: 0, else: lost
    link = %{link | received: link.received + 1, lost: link.lost + lost, last_seen_ms: now_ms}
    %{state | link: link, seqs: Map.put(seqs, compid, seq), link_quality: LinkQuality.frames(state.link_quality, 1, lost)}
  end

  defp message(state, compid, %M.Heartbeat{type: type} = hb) when compid in @camera_compids or type == @camera_type do
    _ = hb
    %{state | components: MapSet.put(state.components, :camera)}
  end

  defp message(state, _compid, %M.Heartbeat{type: @gimbal_type}),
    do: %{state | components: MapSet.put(state.components, :gimbal)}

  # A GCS or another non-vehicle component on the same system says nothing of the vehicle.
  defp message(state, _compid, %M.Heartbeat{autopilot: 8}), do: state

  # The vehicle's identity comes from its autopilot: component 1 (MAV_COMP_ID_AUTOPILOT1)
  # when there is one, else the first component heard with an autopilot; other
  # components (an ADS-B receiver, a companion computer) say nothing of it.
  defp message(%{autopilot_compid: known} = state, compid, %M.Heartbeat{})
       when known != nil and compid != known and compid != 1,
       do: state

  defp message(state, compid, %M.Heartbeat{} = hb) do
    autopilot =
      case hb.autopilot do
        3 -> :ardupilot
        12 -> :px4
        _ -> :other
      end

    %{
      state
      | autopilot_compid: compid,
        type: hb.type,
        autopilot: autopilot,
        mode: Modes.name(autopilot, hb.type, hb.custom_mode),
        armed: (hb.base_mode &&& 128) != 0,
        system_status: hb.system_status
    }
  end

  defp message(state, compid, %M.AutopilotVersion{} = version) when compid == 1 or compid == state.autopilot_compid,
    do: %{state | uid: unique_id(version)}

  defp message(state, _compid, %M.SysStatus{battery_remaining: remaining}) when remaining >= 0 and remaining <= 100,
    do: %{state | battery: remaining / 100}

  defp message(state, _compid, %M.BatteryStatus{id: 0, battery_remaining: remaining}) when remaining >= 0 and remaining <= 100,
    do: %{state | battery: remaining / 100}

  # ArduPilot reports 0, 0 until its position estimate has an origin (SITL
  # for its first seconds): no position yet.
  defp message(state, compid, %M.GlobalPositionInt{lat: 0, lon: 0} = p), do: boot_clock(state, compid, p.time_boot_ms)

  defp message(state, compid, %M.GlobalPositionInt{} = p) do
    state = boot_clock(state, compid, p.time_boot_ms)

    position = %{
      lat: p.lat / 1.0e7,
      lon: p.lon / 1.0e7,
      alt: p.alt / 1000,
      relative_alt: p.relative_alt / 1000,
      heading: if(p.hdg == 65_535, do: nil, else: p.hdg / 100),
      velocity: {p.vx / 100, p.vy / 100, -p.vz / 100}
    }

    %{state | position: position}
  end

  defp message(state, _compid, %M.HomePosition{} = h),
    do: %{state | home: %{lat: h.latitude / 1.0e7, lon: h.longitude / 1.0e7, alt: h.altitude / 1000}}

  defp message(state, _compid, %M.MissionCurrent{} = m) do
    mission_state =
      case m.mission_state do
        1 -> :no_mission
        2 -> :not_started
        3 -> :active
        4 -> :paused
        5 -> :complete
        _ -> nil
      end

    %{state | mission: %{state.mission | current: m.seq, total: m.total, state: mission_state}}
  end

  defp message(state, _compid, %M.MissionItemReached{seq: seq}), do: %{state | mission: %{state.mission | reached: seq}}

  defp message(state, _compid, %M.ExtendedSysState{landed_state: landed}) do
    landed =
      case landed do
        1 -> :on_ground
        2 -> :in_air
        3 -> :takeoff
        4 -> :landing
        _ -> nil
      end

    %{state | landed: landed}
  end

  defp message(state, _compid, %M.Statustext{severity: severity, text: text}),
    do: %{state | status_texts: Enum.take([{severity, text} | state.status_texts], @max_texts)}

  defp message(state, _compid, _other), do: state

  @doc """
  The state once the vehicle's mission list is being replaced (an upload or a
  clear has begun): what was known of the previous mission (the item reached,
  current, total, state) no longer describes it, so it is unknown until the
  vehicle reports again. Otherwise the next mission would start "at" the
  previous one's last item reached, and reaching an item of the same number
  would go unnoticed.
  """
  @spec mission_replaced(t()) :: t()
  def mission_replaced(%__MODULE__{} = state), do: %{state | mission: new(state.id).mission}

  @doc """
  Whether the vehicle says it is still booting (HEARTBEAT `system_status`
  MAV_STATE_UNINIT or MAV_STATE_BOOT). ArduCopter already answers the mission
  protocol then, refusing every upload with NO_SPACE.
  """
  @spec booting?(t()) :: boolean()
  def booting?(%{system_status: status}), do: status in [0, 1]

  @doc """
  Whether the vehicle has been heard and has booted: its type is known and
  it reports a MAV_STATE past BOOT.
  """
  @spec ready?(t()) :: boolean()
  def ready?(%{type: type, system_status: status} = state), do: type != nil and status != nil and not booting?(state)

  @doc """
  The STATUSTEXTs of `now` (newest first, as in `status_texts`) that came
  after `before`, an earlier `status_texts` of the same vehicle: what the
  autopilot said in between.

      iex> Dolphin.Vehicles.State.texts_since([{6, "b"}, {6, "a"}], [{4, "c"}, {6, "b"}, {6, "a"}])
      [{4, "c"}]
  """
  @spec texts_since([{integer(), String.t()}], [{integer(), String.t()}]) :: [{integer(), String.t()}]
  def texts_since(before, now) do
    k = Enum.find(0..length(now), fn k -> Enum.drop(now, k) == Enum.take(before, length(now) - k) end)
    Enum.take(now, k)
  end

  @doc """
  An autopilot's unique id from its AUTOPILOT_VERSION, as one integer: its
  `uid2` (18 bytes, big-endian) when it has one, as ArduPilot's has (its
  `uid` is 0), else its `uid`; 0 when it reports neither.

      iex> alias Dolphin.MAVLink.Ardupilotmega.AutopilotVersion
      iex> Dolphin.Vehicles.State.unique_id(%AutopilotVersion{uid: 0, uid2: [0x31, 0x2a] ++ List.duplicate(0, 16)})
      0x312A00000000000000000000000000000000
      iex> Dolphin.Vehicles.State.unique_id(%AutopilotVersion{uid: 77})
      77
  """
  @spec unique_id(M.AutopilotVersion.t()) :: non_neg_integer()
  def unique_id(%M.AutopilotVersion{uid: uid, uid2: uid2}) do
    case :binary.decode_unsigned(:erlang.list_to_binary(uid2)) do
      0 -> uid
      long -> long
    end
  end

  @doc """
  The public fields that differ between two states, as `{field, new_value}`
  (link counters excepted: they change with every frame; the link's figures
  as `{:link_quality, figures}`).
  """
  @spec changes(t(), t()) :: [{atom(), term()}]
  def changes(%__MODULE__{} = old, %__MODULE__{} = new) do
    # Field by field, written out: a comprehension over the fields' names
    # called a closure per field, a fifth of a moving vehicle's fold.
    fields =
      []
      |> changed(:sensors, old.sensors, new.sensors)
      |> changed(:components, old.components, new.components)
      |> changed(:uid, old.uid, new.uid)
      |> changed(:status_texts, old.status_texts, new.status_texts)
      |> changed(:landed, old.landed, new.landed)
      |> changed(:mission, old.mission, new.mission)
      |> changed(:battery, old.battery, new.battery)
      |> changed(:home, old.home, new.home)
      |> changed(:position, old.position, new.position)
      |> changed(:system_status, old.system_status, new.system_status)
      |> changed(:armed, old.armed, new.armed)
      |> changed(:mode, old.mode, new.mode)
      |> changed(:autopilot, old.autopilot, new.autopilot)
      |> changed(:type, old.type, new.type)

    # The link's figures, not its bookkeeping (pending TIMESYNCs, counters).
    case {link_figures(old), link_figures(new)} do
      {same, same} -> fields
      {_, figures} -> fields ++ [{:link_quality, figures}]
    end
  end

  defp changed(fields, _field, old, new) when old == new, do: fields
  defp changed(fields, field, _old, new), do: [{field, new} | fields]

  @doc "The link's round trip (ms) and loss both ways, nil until measured: see `Dolphin.Vehicles.LinkQuality`."
  @spec link_figures(t()) :: LinkQuality.figures()
  def link_figures(%__MODULE__{link_quality: q}), do: LinkQuality.figures(q)
end
