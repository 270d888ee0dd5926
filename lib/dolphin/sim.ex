defmodule Dolphin.Sim do
  @moduledoc """
  A built-in fleet of simulated ArduCopters that speak real MAVLink 2 over UDP,
  so that every script runs with no hardware and no external simulator, faster
  than real time — and ArduPlane's planes, ArduRover's rovers and boats and
  ArduSub's submarines (`airframe: :plane | :rover | :boat | :sub`;
  docs/simulator.md, "Other airframes").

      {:ok, link} = Dolphin.Link.connect("udpin:127.0.0.1:0")
      {:ok, [1, 2, 3]} = Dolphin.Sim.start(count: 3, gcs: Dolphin.Link.Connection.port(link), speedup: 20)

  Each vehicle is its own process with its own UDP socket, sending to the
  ground station as ArduPilot SITL's `--serial0 udpclient:HOST:PORT` does, and
  answering at whatever address writes to it. On the protocol surface a ground
  station uses, it behaves as ArduCopter was seen to (see ARDUPILOT.md in the
  project's shared notes; a rover, boat or submarine as ArduRover and ArduSub,
  docs/ardupilot.md):

    * HEARTBEAT at 1 Hz with ArduCopter's custom modes and the armed flag; a
      camera component (compid 100) with its own heartbeat when it has one;
    * nothing else but STATUSTEXT and TIMESYNC until streams are asked for (REQUEST_DATA_STREAM,
      MAV_CMD_SET_MESSAGE_INTERVAL, MAV_CMD_REQUEST_MESSAGE): SYS_STATUS,
      BATTERY_STATUS, GLOBAL_POSITION_INT, GPS_RAW_INT, ATTITUDE, VFR_HUD,
      MISSION_CURRENT, EXTENDED_SYS_STATE, HOME_POSITION, AUTOPILOT_VERSION;
    * COMMAND_ACK for every command; modes by number (STABILIZE 0, AUTO 3,
      GUIDED 4, LOITER 5, RTL 6, LAND 9, BRAKE 17 and the rest); arming refused
      in AUTO, until the position estimate is ready (`:ekf_ready_ms` after
      boot, 15 s by default) and on a low battery, each with ArduPilot's
      STATUSTEXT; auto-disarm 10 s after arming on the ground;
    * the mission protocol's vehicle side (items asked for with MISSION_REQUEST,
      item 0 is home, retries and timeouts, fence and rally lists);
    * flight: take-off, waypoints with acceptance radius and hold time, loiters
      (unlimited, turns, time: circles of the given radius), RTL (the item is
      reached only after landing), LAND, delays, speed and altitude changes,
      DO_SET_HOME, DO_JUMP, camera commands (photos counted and reported with
      CAMERA_IMAGE_CAPTURED); GUIDED holds and flies to DO_REPOSITION targets,
      BRAKE stops and holds, LOITER and the other pilot modes sink without RC
      throttle, land and disarm; cruise 10 m/s, climb 2.5 m/s, descent 1.5 m/s;
    * a battery that drains while armed in proportion to effort (a 3300 mAh
      pack at ~30 A: ~0.25 % a second in flight) and charges while disarmed
      on the ground at home or at the fleet's charging station (the `:home`
      they are spread around); warnings at 20 % and 10 %, and ArduPilot's
      battery failsafe when asked for (`battery_failsafe: :rtl | :land`);
      as in SITL with the failsafes off, an empty pack does not stop the motors.

  Time is `Dolphin.Clock` time: with a speed-up of K, flight, telemetry rates
  and the vehicles' protocol timers all run K times faster.

  Faults can be put on any vehicle's link at any time (`set_faults/2`, see
  `Dolphin.Sim.Faults`), and a vehicle can be made to vanish (`crash/2`).
  """

  alias Dolphin.Geo
  alias Dolphin.Sim.Copter

  @default_home %{lat: 40.444233, lon: -7.375234, alt: 820.0}
  @spacing 30.0
  @per_row 10

  @typedoc "Where a vehicle boots: `%{lat, lon, alt}` (degrees, metres above mean sea level)."
  @type location :: %{lat: float(), lon: float(), alt: float()}

  @doc """
  Starts simulated vehicles. Options:

    * `:gcs` (required) — where they send: a port on 127.0.0.1, `{address, port}`,
      or an endpoint string `"udpout:HOST:PORT"`;
    * `:count` — how many (default 1), with system ids from `:first_sysid`
      (default 1), or `:sysids` — the exact ids;
    * `:network` — a name for these vehicles as a group that may reuse the
      system ids of vehicles started without it or on another network (most
      vehicles leave the factory as system id 1: several networks of them,
      each on its own link, are several vehicles with one system id, see
      `Dolphin.Vehicles.Id`); the vehicles are then named `{network, sysid}`
      in this module's functions;
    * `:home` — the location they are spread around, `#{@spacing |> round()}` m
      apart in rows of #{@per_row} (default: the report's, 40.444233, -7.375234,
      820 m); or `:homes` — one location per vehicle;
    * `:camera` — `true` (every vehicle), or a list of system ids, that carry a camera;
    * `:speedup` — sets `Dolphin.Clock`'s speed-up factor;
    * `:seed` — seeds the faults' randomness (default 1);
    * `:faults` — faults on every vehicle's link from the start;
    * `:sensors` — the sensors each vehicle's companion computer carries
      (`Dolphin.Sim.Companion`: `:smoke`, `:water_temp`, `:range`): a list
      for every vehicle, or a map of lists by system id; `:world` — what they
      sense, a `Dolphin.Sim.World` or the path of a world file (default: an
      empty world); `:sensor_rate_hz` and `:sensor_noise` (the noise's
      standard deviation), by default the world's `sensors` section's, else
      2 Hz and each model's noise;
    * any vehicle setting: `:airframe` (`:copter`, default, `:plane`, `:rover`,
      `:boat`, `:sub`: whose firmware it behaves as, with that airframe's
      speeds and currents unless given), `:battery` (initial fraction, default 1.0),
      `:boot_ms` (how long it reports MAV_STATE BOOT and refuses uploads
      with NO_SPACE, as ArduCopter does while it boots; default 0),
      `:ekf_ready_ms`, `:charge_rate` (fraction per second, default 0.005),
      `:charger` (where a landed vehicle charges besides its own home:
      default the fleet's `:home`),
      `:capacity_mah`, `:hover_current`, `:cruise_speed`, `:climb_speed`,
      `:descent_speed`, `:wp_radius`, `:rtl_alt`, `:disarm_delay_ms`
      (DISARM_DELAY: a copter armed on the ground with nothing to do
      disarms after it; default 10000, 0 never, as on ArduCopter),
      `:spool_up_ms` (how long the motors spool up before a take-off
      leaves the ground; default 3000, as ArduCopter SITL),
      `:arm_min_battery`, `:battery_low`, `:battery_critical`,
      `:battery_failsafe` (`:none`, `:rtl`, `:land`), `:gcs_failsafe`,
      `:gcs_sysid`, `:request_int` (ask for items with MISSION_REQUEST_INT),
      `:disarms_at_arming` (a fault: the vehicle disarms itself at once
      after each of its next N arms, in the same instant, as ArduRover SITL
      was seen doing once on a loaded host; default 0), `:gives_up_uploads`
      (a fault: each of its next N uploads is dropped at its last item,
      answered MAV_MISSION_ERROR with nothing stored, as a vehicle whose
      patience ran out just then answers once its OPERATION_CANCELLED is
      lost; default 0), `:unacked_commands` (a fault: these commands, by
      MAV_CMD number, are run but never acknowledged, as ArduPilot drops a
      COMMAND_ACK its full link has no room for; default none).

  Every option is checked before anything starts, so that no vehicle is
  started with a value it cannot report in MAVLink or that means nothing:
  locations within latitude -90..90, longitude -180..180 and altitude
  -1000..10000 m (and the fleet, spread around its home, on the map too),
  `:speedup` within `Dolphin.Clock`'s limits (0.01 to 1000), system ids
  1..254, fractions of a pack (`:battery`, `:battery_low`, ...) 0..1,
  durations 0 or more, speeds, accelerations and the like more than 0 and
  at most what a copter could do (`:cruise_speed` 50 m/s, `:hover_current`
  200 A, ...), and the faults as `set_faults/2` takes them.

  Returns the vehicles started (system ids; `{network, sysid}` with `:network`), or a `Dolphin.Sim.Error` (`:bad_option`)
  that says which option was wrong and what it takes.
  """
  @spec start(keyword()) :: {:ok, [byte()]} | {:error, Dolphin.Sim.Error.t()}
  def start(opts) do
    with {:ok, gcs} <- gcs(Keyword.get(opts, :gcs)),
         {:ok, sysids} <- sysids(opts),
         {:ok, config} <- config(opts),
         :ok <- free(Enum.map(sysids, &sim_id(opts[:network], &1))),
         :ok <- faults(opts),
         {:ok, homes, charger} <- places(opts, length(sysids)),
         {:ok, sensing} <- sensing(opts, sysids),
         :ok <- speedup(opts[:speedup]) do
      cameras = cameras(opts[:camera], sysids)
      config = Map.put(config, :charger, charger)

      network = opts[:network]

      Enum.zip(sysids, homes)
      |> Enum.reduce_while({:ok, []}, fn {sysid, home}, {:ok, started} ->
        child =
          {Dolphin.Sim.Vehicle,
           sysid: sysid,
           network: network,
           # Chosen here, so that a vehicle process restarted by its supervisor keeps it.
           uid: Dolphin.Sim.Copter.unique_id(),
           gcs: gcs,
           home: home,
           seed: Keyword.get(opts, :seed, 1),
           faults: Keyword.get(opts, :faults, %{}),
           sensors: Map.get(sensing.sensors, sysid, []),
           world: sensing.world,
           sensor_rate_hz: sensing.rate_hz,
           sensor_noise: sensing.noise,
           config: Map.put(config, :camera, sysid in cameras)}

        case DynamicSupervisor.start_child(Dolphin.Instance.names().sims, child) do
          {:ok, _pid} -> {:cont, {:ok, [sim_id(network, sysid) | started]}}
          {:error, why} -> {:halt, {:error, %Dolphin.Sim.Error{reason: :start_failed, message: "simulated vehicle #{sysid}: #{inspect(why)}"}}}
        end
      end)
      |> case do
        {:ok, started} -> {:ok, Enum.reverse(started)}
        error -> error
      end
    end
  end

  @doc "The airframes the simulator flies (`:airframe`): ArduCopter's, ArduRover's rovers and boats, ArduSub's."
  @spec airframes() :: [atom()]
  def airframes, do: [:copter, :plane, :rover, :boat, :sub]

  @doc "Like `start/1`, raising `ArgumentError` on a bad option."
  @spec start!(keyword()) :: [byte()]
  def start!(opts) do
    case start(opts) do
      {:ok, sysids} -> sysids
      {:error, e} -> raise ArgumentError, Exception.message(e)
    end
  end

  @doc "Stops every simulated vehicle (or one)."
  @spec stop(byte() | :all) :: :ok
  def stop(sysid \\ :all)

  def stop(:all) do
    for sysid <- vehicles(), do: stop(sysid)
    :ok
  end

  def stop(sysid) do
    case whereis(sysid) do
      nil -> :ok
      pid -> DynamicSupervisor.terminate_child(Dolphin.Instance.names().sims, pid) |> then(fn _ -> :ok end)
    end
  end

  @doc "The system ids of the simulated vehicles running now."
  @spec vehicles() :: [byte()]
  def vehicles do
    # The registry forgets a dead process a moment after it dies: ask the process.
    Registry.select(Dolphin.Instance.names().registry, [{{{:sim, :"$1"}, :"$2", :_}, [], [{{:"$1", :"$2"}}]}])
    |> Enum.filter(fn {_id, pid} -> Process.alive?(pid) end)
    |> Enum.map(&elem(&1, 0))
    |> Enum.sort()
  end

  @doc """
  What a simulated vehicle is doing, as the simulator sees it (the truth, not
  the telemetry): `mode`, `armed`, `landed`, `position` (`%{lat, lon, alt,
  relative_alt}`), `velocity`, `home`, `battery`, `mission` (its items,
  home excluded), `current`, `mission_state`, `photos`, `faults`, its UDP
  `port`, `time_ms` (vehicle time since boot) and `lag_ms` (how far it is
  behind the clock).
  """
  @spec info(byte()) :: {:ok, map()} | {:error, :unknown_vehicle}
  def info(sysid), do: call(sysid, :info)

  @doc "Changes the faults of a vehicle's link (see `Dolphin.Sim.Faults`); `%{}` keeps them."
  @spec set_faults(byte(), map() | keyword()) :: :ok | {:error, :unknown_vehicle | Dolphin.Sim.Error.t()}
  def set_faults(sysid, faults), do: call(sysid, {:faults, faults})

  @doc "Sets a vehicle's battery charge (a fraction of full): for tests and demonstrations."
  @spec set_battery(byte(), number()) :: :ok | {:error, :unknown_vehicle}
  def set_battery(sysid, fraction) when is_number(fraction) and fraction >= 0 and fraction <= 1, do: call(sysid, {:set, :battery, fraction})

  @doc """
  Kills a vehicle's process, as if it had been destroyed: the ground station
  stops hearing it. With `reboot: true` it comes back at once as a freshly
  booted autopilot at its first boot position, with a full battery and no
  mission (what a crashed process held is lost).
  """
  @spec crash(byte(), keyword()) :: :ok | {:error, :unknown_vehicle}
  def crash(sysid, opts \\ []) do
    case whereis(sysid) do
      nil ->
        {:error, :unknown_vehicle}

      pid ->
        if Keyword.get(opts, :reboot, false) do
          # An abnormal exit: the supervisor restarts the (transient) vehicle.
          Process.exit(pid, :kill)
        else
          DynamicSupervisor.terminate_child(Dolphin.Instance.names().sims, pid)
        end

        :ok
    end
  end

  @doc """
  Does `action` to a vehicle the moment it reaches mission item `seq`, right
  after it reports MISSION_ITEM_REACHED for it: what a test or a demonstration
  needs to lose a vehicle at a given point of its mission, exactly there,
  however far behind the ground station's hearing runs. `action` is `:crash`
  (nothing more is heard from it and its process ends, as `crash/1`),
  `{:faults, faults}` (as `set_faults/2`: `{:faults, silence: true}`) or
  `{:battery, fraction}` (as `set_battery/2`). Each is done once; several
  for one item are done in the order given; a reboot forgets those not
  done yet. A crash silences the vehicle at once and ends its process once
  the frames its faults hold back (latency, reordering) have gone out.
  """
  @spec on_item_reached(byte(), non_neg_integer(), :crash | {:faults, map() | keyword()} | {:battery, number()}) ::
          :ok | {:error, :unknown_vehicle | Dolphin.Sim.Error.t()}
  def on_item_reached(sysid, seq, action) when is_integer(seq) and seq >= 0 do
    case action do
      :crash -> call(sysid, {:on_item_reached, seq, action})
      {:battery, f} when is_number(f) and f >= 0 and f <= 1 -> call(sysid, {:on_item_reached, seq, action})
      {:faults, faults} when is_map(faults) or is_list(faults) -> call(sysid, {:on_item_reached, seq, action})
      other -> Dolphin.Sim.Error.bad_option("bad action #{inspect(other)} at item #{seq}: :crash, {:faults, faults} or {:battery, fraction}")
    end
  end

  defp call(sysid, request) do
    case whereis(sysid) do
      nil -> {:error, :unknown_vehicle}
      pid -> GenServer.call(pid, request)
    end
  catch
    :exit, {:noproc, _} -> {:error, :unknown_vehicle}
  end

  defp sim_id(nil, sysid), do: sysid
  defp sim_id(network, sysid), do: {network, sysid}

  defp whereis(sysid) do
    case Registry.lookup(Dolphin.Instance.names().registry, {:sim, sysid}) do
      [{pid, _}] -> if Process.alive?(pid), do: pid
      [] -> nil
    end
  end

  # --- options ----------------------------------------------------------------

  defp gcs(port) when is_integer(port) and port in 1..65_535, do: {:ok, {{127, 0, 0, 1}, port}}
  defp gcs({address, port} = gcs) when is_tuple(address) and is_integer(port), do: {:ok, gcs}

  defp gcs(endpoint) when is_binary(endpoint) do
    case Dolphin.Link.Endpoint.parse(endpoint) do
      {:ok, %{kind: :udpout, address: address, port: port}} -> {:ok, {address, port}}
      {:ok, _} -> Dolphin.Sim.Error.bad_option("the simulator sends to a ground station: give it udpout:HOST:PORT, not #{endpoint}")
      {:error, e} -> Dolphin.Sim.Error.bad_option(Exception.message(e))
    end
  end

  defp gcs(nil), do: Dolphin.Sim.Error.bad_option("the simulator needs :gcs, where the ground station listens (a port, {address, port} or \"udpout:HOST:PORT\")")
  defp gcs(other), do: Dolphin.Sim.Error.bad_option("bad :gcs #{inspect(other)}: a port, {address, port} or \"udpout:HOST:PORT\"")

  defp sysids(opts) do
    case Keyword.fetch(opts, :sysids) do
      {:ok, ids} when is_list(ids) and ids != [] ->
        if Enum.all?(ids, &(is_integer(&1) and &1 in 1..254)) and length(Enum.uniq(ids)) == length(ids),
          do: {:ok, ids},
          else: Dolphin.Sim.Error.bad_option("bad :sysids #{inspect(ids, charlists: :as_lists)}: distinct system ids in 1..254")

      {:ok, other} ->
        Dolphin.Sim.Error.bad_option("bad :sysids #{inspect(other, charlists: :as_lists)}: a list of system ids")

      :error ->
        count = Keyword.get(opts, :count, 1)
        first = Keyword.get(opts, :first_sysid, 1)

        cond do
          not is_integer(count) or count < 1 -> Dolphin.Sim.Error.bad_option("bad :count #{inspect(count)}: at least 1 vehicle")
          not is_integer(first) or first < 1 or first + count - 1 > 254 -> Dolphin.Sim.Error.bad_option("system ids #{first}..#{first + count - 1} do not fit in 1..254")
          true -> {:ok, Enum.to_list(first..(first + count - 1))}
        end
    end
  end

  # What each vehicle setting may be: the vehicle must be able to report
  # what it does in MAVLink's fields (a battery of 5.0 is 500 %, which
  # BATTERY_STATUS cannot carry) and the setting must mean something.
  @settings %{
    battery: {:fraction, "a fraction of a full pack"},
    arm_min_battery: {:fraction, "a fraction of a full pack"},
    battery_low: {:fraction, "a fraction of a full pack"},
    battery_critical: {:fraction, "a fraction of a full pack"},
    charge_rate: {:fraction, "a fraction of a full pack a second"},
    boot_ms: {:at_least_0, "milliseconds"},
    ekf_ready_ms: {:at_least_0, "milliseconds"},
    disarm_delay_ms: {:at_least_0, "milliseconds"},
    spool_up_ms: {:at_least_0, "milliseconds"},
    rtl_alt: {:at_least_0, "metres"},
    capacity_mah: {{:positive, 1_000_000}, "mAh"},
    hover_current: {{:positive, 200}, "amperes"},
    cruise_speed: {{:positive, 50}, "m/s"},
    # 0: motors that cannot lift it (a fault a test may simulate: armed on the ground for ever).
    climb_speed: {{:at_least_0, 50}, "m/s"},
    descent_speed: {{:positive, 50}, "m/s"},
    circle_speed: {{:positive, 50}, "m/s"},
    accel: {{:positive, 100}, "m/s²"},
    brake_accel: {{:positive, 100}, "m/s²"},
    accel_z: {{:positive, 100}, "m/s²"},
    circle_rate: {{:positive, 90}, "degrees a second"},
    wp_radius: {{:positive, 1000}, "metres"},
    battery_failsafe: {{:one_of, [:none, :rtl, :land]}, nil},
    airframe: {{:one_of, [:copter, :plane, :rover, :boat, :sub]}, nil},
    gcs_failsafe: {:boolean, nil},
    disarms_at_arming: {{:one_of, Enum.to_list(0..100)}, "a number of arms"},
    gives_up_uploads: {{:one_of, Enum.to_list(0..100)}, "a number of uploads"},
    unacked_commands: {:commands, "MAV_CMD numbers"},
    request_int: {:boolean, nil},
    gcs_sysid: {{:one_of, Enum.to_list(1..255)}, "a system id"}
  }

  defp config(opts) do
    known = Map.keys(Copter.defaults()) -- [:camera, :charger]
    config = opts |> Keyword.take(known) |> Map.new()

    case Enum.find_value(config, fn {k, v} -> setting_problem(k, v) end) do
      nil -> {:ok, config}
      problem -> Dolphin.Sim.Error.bad_option(problem)
    end
  end

  defp setting_problem(key, value) do
    {rule, unit} = Map.fetch!(@settings, key)

    {ok?, allowed} =
      case rule do
        :fraction -> {is_number(value) and value >= 0 and value <= 1, "#{unit}, from 0 to 1"}
        :at_least_0 -> {is_number(value) and value >= 0, "#{unit}, 0 or more"}
        {:at_least_0, max} -> {is_number(value) and value >= 0 and value <= max, "#{unit}, from 0 to #{max}"}
        {:positive, max} -> {is_number(value) and value > 0 and value <= max, "#{unit}, more than 0 and at most #{max}"}
        {:one_of, [_ | _] = values} when length(values) > 10 -> {value in values, "#{unit} from #{hd(values)} to #{List.last(values)}"}
        {:one_of, values} -> {value in values, "one of #{Enum.map_join(values, ", ", &inspect/1)}"}
        :boolean -> {is_boolean(value), "true or false"}
        :commands -> {is_list(value) and Enum.all?(value, &(is_integer(&1) and &1 in 0..65_535)), "a list of #{unit} (0 to 65535)"}
      end

    unless ok?, do: "bad #{inspect(key)} #{inspect(value)}: #{allowed}"
  end

  defp free(sysids) do
    case Enum.filter(sysids, &whereis/1) do
      [] -> :ok
      taken -> Dolphin.Sim.Error.bad_option("simulated vehicles #{Dolphin.Fleet.VehicleSet.format(taken)} are already running")
    end
  end

  defp speedup(nil), do: :ok

  defp speedup(k) do
    if Dolphin.Clock.speedup?(k),
      do: Dolphin.Clock.set_speedup(k),
      else: Dolphin.Sim.Error.bad_option("bad :speedup: " <> Dolphin.Clock.speedup_rule(k))
  end

  # Checked here: a vehicle that cannot take them would fail in its start.
  defp faults(opts) do
    case Keyword.get(opts, :faults, %{}) do
      faults when is_map(faults) or is_list(faults) ->
        Dolphin.Sim.Faults.new(faults, 1)
        :ok

      other ->
        Dolphin.Sim.Error.bad_option("bad :faults #{inspect(other)}: a map or keyword list of faults (see Dolphin.Sim.Faults)")
    end
  rescue
    e in ArgumentError -> Dolphin.Sim.Error.bad_option(Exception.message(e))
  end

  # Where the vehicles boot and where they charge, or what is wrong with them.
  defp places(opts, count) do
    homes = homes(count, opts)
    charger = opts[:charger] || opts[:home] || if(opts[:homes], do: hd(homes), else: @default_home)
    {:ok, homes, location(charger, ":charger")}
  rescue
    e in ArgumentError -> Dolphin.Sim.Error.bad_option(Exception.message(e))
  end

  @doc """
  Where `count` vehicles boot, as `start/1` spreads them: `opts[:homes]` (one
  location per vehicle), else `#{@spacing |> round()}` m apart in rows of
  #{@per_row} around `opts[:home]` (default the report's home). Raises
  `ArgumentError` for bad locations. The SITL fleet (`Dolphin.SITL`) uses it too.
  """
  @spec homes(pos_integer(), keyword()) :: [location()]
  def homes(count, opts) do
    case Keyword.fetch(opts, :homes) do
      {:ok, homes} when is_list(homes) ->
        if length(homes) != count, do: raise(ArgumentError, "bad :homes: #{length(homes)} locations for #{count} vehicles")
        Enum.map(homes, &location/1)

      :error ->
        center = location(Keyword.get(opts, :home, @default_home))
        columns = min(count, @per_row)

        for i <- 0..(count - 1) do
          row = div(i, @per_row)
          column = rem(i, @per_row)
          spread(center, Geo.tangent_offset(center, -row * @spacing, (column - (columns - 1) / 2) * @spacing))
        end
    end
  end

  # The vehicles report where they are in MAVLink's degE7 and millimetre
  # fields: a latitude beyond ±90 (or a longitude beyond ±180) is no place,
  # and one beyond ±214.7° cannot even be sent.
  defp location(place, what \\ "home")
  defp location(%{lat: lat, lon: lon} = l, what), do: checked(lat, lon, Map.get(l, :alt, 0), what)
  defp location({lat, lon, alt}, what), do: checked(lat, lon, alt, what)
  defp location(other, what), do: raise(ArgumentError, "bad #{what} #{inspect(other)}: %{lat: ..., lon: ..., alt: ...} or {lat, lon, alt}")

  defp checked(lat, lon, alt, what) do
    cond do
      not (is_number(lat) and is_number(lon) and is_number(alt)) -> raise ArgumentError, "bad #{what} #{inspect({lat, lon, alt})}: latitude, longitude and altitude are numbers"
      lat < -90 or lat > 90 -> raise ArgumentError, "bad #{what}: the latitude #{lat} is not within -90..90"
      lon < -180 or lon > 180 -> raise ArgumentError, "bad #{what}: the longitude #{lon} is not within -180..180"
      alt < -1000 or alt > 10_000 -> raise ArgumentError, "bad #{what}: the altitude #{alt} m is not within -1000..10000 (metres above mean sea level)"
      true -> %{lat: lat * 1.0, lon: lon * 1.0, alt: alt * 1.0}
    end
  end

  # The fleet is spread on the tangent plane at its home: near a pole (or
  # across the 180th meridian) the plane's places are off the map.
  defp spread(center, %{lat: lat, lon: lon} = place) do
    if lat >= -90 and lat <= 90 and lon >= -180 and lon <= 180,
      do: place,
      else: raise(ArgumentError, "bad home: vehicles #{round(@spacing)} m apart around #{center.lat}, #{center.lon} would stand at #{Float.round(lat, 6)}, #{Float.round(lon, 6)}, off the map (too near a pole or the 180th meridian)")
  end

  # The sensors each vehicle's companion computer carries, and what they sense.
  defp sensing(opts, sysids) do
    models = Dolphin.Sim.Companion.models()

    sensors =
      case Keyword.get(opts, :sensors, []) do
        list when is_list(list) -> {:ok, Map.new(sysids, &{&1, list})}
        %{} = by_id -> {:ok, by_id}
        other -> {:error, "bad :sensors #{inspect(other)}: a list of sensor models (#{Enum.join(models, ", ")}), or a map of them by system id"}
      end

    with {:ok, sensors} <- sensors,
         nil <- Enum.find_value(sensors, fn {_id, list} -> Enum.find(List.wrap(list), &(&1 not in models)) end) |> unknown_model(models),
         {:ok, world} <- world(Keyword.get(opts, :world)),
         rate = Keyword.get(opts, :sensor_rate_hz),
         true <- rate == nil or (is_number(rate) and rate > 0 and rate <= 50) || {:error, "bad :sensor_rate_hz #{inspect(rate)}: readings a second, more than 0 and at most 50"},
         noise = Keyword.get(opts, :sensor_noise),
         true <- noise == nil or (is_number(noise) and noise >= 0) || {:error, "bad :sensor_noise #{inspect(noise)}: the noise's standard deviation, 0 or more"} do
      {:ok, %{sensors: Map.new(sensors, fn {id, l} -> {id, List.wrap(l)} end), world: world, rate_hz: rate, noise: noise}}
    else
      {:error, why} -> Dolphin.Sim.Error.bad_option(why)
    end
  end

  defp unknown_model(nil, _models), do: nil
  defp unknown_model(model, models), do: {:error, "no sensor model #{inspect(model)}; the simulator's sensors are #{Enum.join(models, ", ")}"}

  defp world(nil), do: {:ok, %Dolphin.Sim.World{}}
  defp world(%Dolphin.Sim.World{} = world), do: {:ok, world}
  defp world(path) when is_binary(path), do: Dolphin.Sim.World.read(path)
  defp world(other), do: {:error, "bad :world #{inspect(other)}: a world (Dolphin.Sim.World) or the path of a world file"}

  defp cameras(true, sysids), do: sysids
  defp cameras(list, _sysids) when is_list(list), do: list
  defp cameras(_, _sysids), do: []
end
