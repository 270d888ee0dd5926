defmodule Dolphin.Vehicles.View do
  @moduledoc """
  One vehicle as the rest of the ground station sees it, whatever its source
  (see `Dolphin.Fleet.Source`): identity, class, payloads and the live state
  that conditions read and the fleet picks by.

  The vehicle's owner (its process in `Dolphin.Vehicles`, through
  `Dolphin.Vehicles.Views.put/1`, or a fake source) publishes a new view on
  topic `{:vehicle, id}` of `Dolphin.PubSub` each time one of these
  fields changes, as `{:view, %View{}}`: subscribers take the latest view
  whole and never rebuild one from changes. What changed between two views
  that a user hears of is `transitions/2`.

  | field | meaning |
  | --- | --- |
  | `id` | the vehicle's id: its system id, or its qualified name `"SYSID@NETWORK"` when another vehicle has that system id (`Dolphin.Vehicles.Id`) |
  | `network` | where it was first heard (`Dolphin.Vehicles.Id.network/1`), `nil` for a vehicle no link of this node hears |
  | `type` | `:uav`, `:ugv`, `:usv`, `:uuv`, `:other`, or `nil` while unknown |
  | `airframe` | `:copter`, `:plane`, `:quadplane`, `:rover`, `:boat`, `:sub` (`airframe/2`), or `nil`: unknown, or a MAV_TYPE no mission of the language is made for |
  | `mav_type` | its HEARTBEAT's MAV_TYPE number (2 a quadrotor, ...), `nil` while unknown |
  | `autopilot` | `:ardupilot`, `:px4`, `:other` or `nil` while unknown |
  | `uid` | its autopilot's unique id (AUTOPILOT_VERSION; 0: it has none), `nil` until reported |
  | `payloads` | sorted list of atoms, e.g. `[:camera]` |
  | `battery` | remaining fraction 0.0..1.0, `nil` until reported |
  | `position` | `Dolphin.Geo.Location` (height above mean sea level) or `nil` |
  | `relative_altitude` | metres above home, or `nil` |
  | `velocity` | `{north, east, up}` in metres per second, or `nil` |
  | `mode` | flight mode name (`:guided`, `:auto`, ...) or `nil` |
  | `armed?`, `connected?` | booleans |
  | `mission_progress` | `{reached, total}`: last mission item reached (0 before the first) and items in the mission, since the mission was last uploaded; `nil` until the vehicle reports its mission |
  | `landed` | `:on_ground`, `:in_air`, `:takeoff`, `:landing` or `nil` |
  | `mission` | the mission on the vehicle as it reports it: `%{current, total, state, reached}` (`state` `:active`, `:complete`, ... from MISSION_CURRENT; all `nil` until reported, and again once a new mission is uploaded) |
  | `home` | `Dolphin.Geo.Location` of its home, or `nil` until reported |
  | `system_status` | MAV_STATE number (0 UNINIT, 1 BOOT, ... 4 ACTIVE), `nil` until reported |
  | `link` | `%{rtt_ms, loss_in, loss_out}`: round trip and loss each way, `nil`s until measured (`Dolphin.Vehicles.LinkQuality`) |
  | `boot_ms` | the autopilot's own clock (GLOBAL_POSITION_INT's `time_boot_ms`) at its latest position report, `nil` until heard: of two views of one vehicle from two paths or two stations, the one with the later clock is the newer (`newer?/2`) |
  | `sensors` | the readings of the sensors scripts declared (`Dolphin.Sensors.Readings`), by source; `%{}` until one is heard |
  | `status_texts` | the autopilot's last STATUSTEXTs, `{severity, text}`, newest first (see `Dolphin.Vehicles.State`); what it said since an earlier view is `Dolphin.Vehicles.State.texts_since/2` of the two |
  """

  defstruct id: nil,
            network: nil,
            type: nil,
            airframe: nil,
            mav_type: nil,
            autopilot: nil,
            uid: nil,
            payloads: [],
            battery: nil,
            position: nil,
            relative_altitude: nil,
            velocity: nil,
            mode: nil,
            armed?: false,
            connected?: true,
            mission_progress: nil,
            landed: nil,
            mission: %{current: nil, total: nil, state: nil, reached: nil},
            home: nil,
            system_status: nil,
            link: %{rtt_ms: nil, loss_in: nil, loss_out: nil},
            boot_ms: nil,
            status_texts: [],
            sensors: %{}

  @type class :: :uav | :ugv | :usv | :uuv | :other
  @type airframe :: Dolphin.Airframe.t()
  @type t :: %__MODULE__{
          id: Dolphin.Vehicles.Id.t(),
          network: String.t() | nil,
          type: class() | nil,
          airframe: airframe() | nil,
          mav_type: non_neg_integer() | nil,
          autopilot: atom() | nil,
          uid: non_neg_integer() | nil,
          payloads: [atom()],
          battery: float() | nil,
          position: Dolphin.Geo.Location.t() | nil,
          relative_altitude: float() | nil,
          velocity: {float(), float(), float()} | nil,
          mode: atom() | nil,
          armed?: boolean(),
          connected?: boolean(),
          mission_progress: {non_neg_integer(), non_neg_integer()} | nil,
          landed: atom() | nil,
          mission: %{current: non_neg_integer() | nil, total: non_neg_integer() | nil, state: atom() | nil, reached: non_neg_integer() | nil},
          home: Dolphin.Geo.Location.t() | nil,
          system_status: non_neg_integer() | nil,
          link: %{rtt_ms: non_neg_integer() | nil, loss_in: float() | nil, loss_out: float() | nil},
          boot_ms: non_neg_integer() | nil,
          status_texts: [{non_neg_integer(), String.t()}],
          sensors: Dolphin.Sensors.Readings.t()
        }

  @doc """
  How fast the vehicle moves, metres per second over ground and in height
  together (0.0 while its velocity is not reported).

      iex> Dolphin.Vehicles.View.speed(%Dolphin.Vehicles.View{velocity: {3.0, 4.0, 0.0}})
      5.0
  """
  @spec speed(t()) :: float()
  def speed(%__MODULE__{velocity: {vn, ve, vu}}), do: :math.sqrt(vn * vn + ve * ve + vu * vu)
  def speed(%__MODULE__{}), do: 0.0

  @uav [1, 2, 3, 4, 7, 8, 13, 14, 15, 16, 17, 19, 20, 21, 22, 23, 24, 25, 28, 29, 35, 43, 47]

  @doc """
  The class of a MAV_TYPE number: multirotors, fixed wing, VTOL, helicopters,
  airships are `:uav`; ground rovers `:ugv`; surface boats `:usv`; submarines `:uuv`.

      iex> Dolphin.Vehicles.View.class(2)
      :uav
      iex> Dolphin.Vehicles.View.class(11)
      :usv
  """
  @spec class(non_neg_integer() | nil) :: class() | nil
  def class(nil), do: nil
  def class(type) when type in @uav, do: :uav
  def class(type) when type in [10, 46], do: :ugv
  def class(11), do: :usv
  def class(12), do: :uuv
  def class(_), do: :other

  # MAV_TYPE numbers by airframe: the multirotors and helicopters ArduCopter
  # flies, fixed wing, the VTOL types a quadplane reports, ground rover,
  # surface boat, submarine.
  @copter [2, 3, 4, 13, 14, 15, 29, 35, 43]
  @quadplane [19, 20, 21, 22, 23, 24, 25]

  @doc "The airframes, as `pick(airframe: ...)` names them (`Dolphin.Airframe.all/0`)."
  @spec airframes() :: [airframe()]
  defdelegate airframes, to: Dolphin.Airframe, as: :all

  @doc """
  The airframe of a vehicle whose HEARTBEAT says MAV_TYPE `mav_type` and
  autopilot `autopilot` (as `Dolphin.Vehicles.State` names it): how its
  missions fly (take-off, loiter, landing, what a stop does). Only a flight
  stack's vehicle has one (an `:other` autopilot — a companion computer, a
  gimbal — has none), and only a MAV_TYPE whose missions the language knows:
  anything else (an airship, a balloon) is `nil`, never guessed.

      iex> Dolphin.Vehicles.View.airframe(2, :ardupilot)
      :copter
      iex> Dolphin.Vehicles.View.airframe(1, :ardupilot)
      :plane
      iex> Dolphin.Vehicles.View.airframe(11, :ardupilot)
      :boat
      iex> Dolphin.Vehicles.View.airframe(12, :ardupilot)
      :sub
      iex> Dolphin.Vehicles.View.airframe(7, :ardupilot)
      nil
      iex> Dolphin.Vehicles.View.airframe(2, :other)
      nil
  """
  @spec airframe(non_neg_integer() | nil, atom() | nil) :: airframe() | nil
  def airframe(mav_type, autopilot) when autopilot in [:ardupilot, :px4] do
    cond do
      mav_type in @copter -> :copter
      mav_type == 1 -> :plane
      mav_type in @quadplane -> :quadplane
      mav_type == 10 -> :rover
      mav_type == 11 -> :boat
      mav_type == 12 -> :sub
      true -> nil
    end
  end

  def airframe(_mav_type, _autopilot), do: nil

  @doc """
  The airframe a stand-in of class `type` has when its description names
  none (a fleet file's vehicle, a fake vehicle): the class's most common one.
  Never used for a vehicle heard over MAVLink, whose airframe is its
  heartbeat's (`airframe/2`).

      iex> Enum.map([:uav, :ugv, :usv, :uuv, :other], &Dolphin.Vehicles.View.stand_in_airframe/1)
      [:copter, :rover, :boat, :sub, nil]
  """
  @spec stand_in_airframe(class() | nil) :: airframe() | nil
  def stand_in_airframe(:uav), do: :copter
  def stand_in_airframe(:ugv), do: :rover
  def stand_in_airframe(:usv), do: :boat
  def stand_in_airframe(:uuv), do: :sub
  def stand_in_airframe(_), do: nil

  @doc """
  The class of an airframe.

      iex> Dolphin.Vehicles.View.airframe_class(:quadplane)
      :uav
  """
  @spec airframe_class(airframe()) :: class()
  def airframe_class(airframe) when airframe in [:copter, :plane, :quadplane], do: :uav
  def airframe_class(:rover), do: :ugv
  def airframe_class(:boat), do: :usv
  def airframe_class(:sub), do: :uuv

  @doc """
  How a vehicle's class and airframe read: `"uav copter"`, `"uuv sub"`,
  `"uav, airframe unknown (airship)"` (what its MAV_TYPE says, when the
  airframe is unknown), `"type unknown"` before its first heartbeat.

      iex> Dolphin.Vehicles.View.describe_kind(%Dolphin.Vehicles.View{type: :uav, airframe: :plane, mav_type: 1})
      "uav plane"
      iex> Dolphin.Vehicles.View.describe_kind(%Dolphin.Vehicles.View{type: :uav, mav_type: 7})
      "uav, airframe unknown (airship)"
  """
  @spec describe_kind(t()) :: String.t()
  def describe_kind(%__MODULE__{type: nil, airframe: nil}), do: "type unknown"
  def describe_kind(%__MODULE__{type: type, airframe: nil, mav_type: nil}), do: "#{type}, airframe unknown"
  def describe_kind(%__MODULE__{type: type, airframe: nil, mav_type: n}), do: "#{type}, airframe unknown (#{mav_type_name(n)})"
  def describe_kind(%__MODULE__{type: type, airframe: airframe}), do: "#{type} #{airframe}"

  @doc """
  A MAV_TYPE number in words: `2` is `"quadrotor"`, an unknown number `"MAV_TYPE 99"`.

      iex> Dolphin.Vehicles.View.mav_type_name(11)
      "surface boat"
  """
  @spec mav_type_name(non_neg_integer()) :: String.t()
  def mav_type_name(n) do
    case Dolphin.MAVLink.Ardupilotmega.enum_name(:mav_type, n) do
      {:ok, atom} -> atom |> Atom.to_string() |> String.replace_prefix("mav_type_", "") |> String.replace("_", " ")
      _ -> "MAV_TYPE #{n}"
    end
  end

  @doc """
  Whether `name` names the vehicle of `view`: its id, or its qualified name
  `"SYSID@NETWORK"` (which the first vehicle heard with a system id answers
  to as well, `Dolphin.Vehicles.Id`).

      iex> v = %Dolphin.Vehicles.View{id: 1, network: "radio1"}
      iex> {Dolphin.Vehicles.View.named?(v, 1), Dolphin.Vehicles.View.named?(v, "1@radio1"), Dolphin.Vehicles.View.named?(v, "1@radio2")}
      {true, true, false}
  """
  @spec named?(t(), Dolphin.Vehicles.Id.t()) :: boolean()
  def named?(%__MODULE__{id: id}, id), do: true
  def named?(%__MODULE__{id: id, network: network}, name) when is_binary(name) and is_binary(network), do: is_integer(id) and name == "#{id}@#{network}"
  def named?(_view, _name), do: false

  @doc """
  The view of a vehicle's `Dolphin.Vehicles.State`: `lost` says whether it
  is silent, `payloads` are configured payloads added to its components'.

      iex> st = %{Dolphin.Vehicles.State.new(7) | type: 2, battery: 0.5, position: %{lat: 41.0, lon: -8.0, alt: 120.0, relative_alt: 20, heading: 0}}
      iex> v = Dolphin.Vehicles.View.of(st, false, [:sidescan])
      iex> {v.id, v.type, v.battery, v.position.h, v.relative_altitude, v.payloads, v.mission_progress}
      {7, :uav, 0.5, 120.0, 20.0, [:sidescan], nil}
  """
  @spec of(Dolphin.Vehicles.State.t(), boolean(), [atom()]) :: t()
  def of(state, lost, payloads) do
    {position, relative} =
      case state.position do
        nil -> {nil, nil}
        p -> {Dolphin.Geo.Location.new(p.lat, p.lon, p.alt), p.relative_alt * 1.0}
      end

    %__MODULE__{
      id: state.id,
      type: class(state.type),
      airframe: airframe(state.type, state.autopilot),
      mav_type: state.type,
      autopilot: state.autopilot,
      uid: state.uid,
      payloads: Enum.sort(Enum.uniq(Enum.to_list(state.components) ++ payloads)),
      battery: state.battery,
      position: position,
      relative_altitude: relative,
      velocity: state.position && Map.get(state.position, :velocity),
      mode: state.mode,
      armed?: state.armed,
      connected?: not lost,
      mission_progress: progress(state.mission),
      landed: state.landed,
      mission: state.mission,
      home: state.home && Dolphin.Geo.Location.new(state.home.lat, state.home.lon, state.home.alt),
      system_status: state.system_status,
      link: Map.take(Dolphin.Vehicles.State.link_figures(state), [:rtt_ms, :loss_in, :loss_out]),
      boot_ms: state.boot && elem(state.boot, 0),
      status_texts: state.status_texts,
      sensors: state.sensors
    }
  end

  @doc """
  Whether view `a` shows the vehicle later than view `b` does, by the
  autopilot's own clock (`boot_ms`): two stations that hear one vehicle each
  have their view of it, one of them a little behind the other. Views that
  do not both carry the clock count as newer: nothing says otherwise. (An
  autopilot that restarted has its clock start again: whoever waits for a
  newer view bounds the wait, as `Dolphin.Cluster.Mirror` does.)

      iex> alias Dolphin.Vehicles.View
      iex> View.newer?(%View{boot_ms: 1_200}, %View{boot_ms: 1_000})
      true
      iex> View.newer?(%View{boot_ms: 1_000}, %View{boot_ms: 1_000})
      false
      iex> View.newer?(%View{boot_ms: nil}, %View{boot_ms: 1_000})
      true
  """
  @spec newer?(t(), t()) :: boolean()
  def newer?(%__MODULE__{boot_ms: a}, %__MODULE__{boot_ms: b}) when is_integer(a) and is_integer(b), do: a > b
  def newer?(%__MODULE__{}, %__MODULE__{}), do: true

  # No MISSION_CURRENT yet: the total is not known, nor is the progress.
  defp progress(%{total: nil}), do: nil
  defp progress(m), do: {m.reached || 0, m.total}

  @doc """
  The events (`Dolphin.Events` names and metadata) of a vehicle going
  from view `old` (`nil`: none yet) to view `new`, in the order they are
  emitted: `vehicle_discovered` once the type is known (a vehicle whose
  type is unknown is not announced, nor are its changes), then
  `mode_changed`, `armed` / `disarmed`, `mission_item_reached` and last
  `vehicle_lost` / `vehicle_reconnected`. A first view announces only the
  discovery: what the vehicle was doing before it was heard is no change.

      iex> alias Dolphin.Vehicles.View
      iex> View.transitions(nil, %View{id: 3, type: :uav, mode: :guided})
      [{:vehicle_discovered, %{vehicle: 3, type: :uav, airframe: nil}}]
      iex> View.transitions(%View{id: 3, type: :uav}, %View{id: 3, type: :uav, mode: :auto, armed?: true, mission_progress: {2, 5}})
      [{:mode_changed, %{vehicle: 3, mode: :auto}}, {:armed, %{vehicle: 3}}, {:mission_item_reached, %{vehicle: 3, seq: 2}}]
      iex> View.transitions(%View{id: 3, type: :uav}, %View{id: 3, type: :uav, connected?: false})
      [{:vehicle_lost, %{vehicle: 3}}]
  """
  @spec transitions(t() | nil, t()) :: [{atom(), map()}]
  def transitions(old, %__MODULE__{} = new) do
    discovered = if new.type != nil and (old == nil or old.type == nil), do: [{:vehicle_discovered, %{vehicle: new.id, type: new.type, airframe: new.airframe}}], else: []

    case old do
      nil -> discovered
      old -> discovered ++ changes(old, new) ++ link(old, new)
    end
  end

  defp changes(_old, %{type: nil}), do: []

  defp changes(old, new) do
    mode = if old.mode != new.mode and new.mode != nil, do: [{:mode_changed, %{vehicle: new.id, mode: new.mode}}], else: []
    armed = if old.armed? != new.armed?, do: [{if(new.armed?, do: :armed, else: :disarmed), %{vehicle: new.id}}], else: []

    reached =
      case {old.mission_progress, new.mission_progress} do
        {{reached, _}, {reached, _}} -> []
        {_, {reached, _}} when reached > 0 -> [{:mission_item_reached, %{vehicle: new.id, seq: reached}}]
        _ -> []
      end

    mode ++ armed ++ reached
  end

  defp link(%{connected?: same}, %{connected?: same}), do: []
  defp link(_old, %{connected?: false, id: id}), do: [{:vehicle_lost, %{vehicle: id}}]
  defp link(_old, %{connected?: true, id: id}), do: [{:vehicle_reconnected, %{vehicle: id}}]
end
