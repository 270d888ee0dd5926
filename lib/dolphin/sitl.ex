defmodule Dolphin.SITL do
  @moduledoc """
  A fleet of real ArduPilot vehicles: instances of ArduPilot's
  software-in-the-loop build (its own flight code on a physics model) on a
  local link, as `mix dolphin.run SCRIPT --sitl N` (N copters) or `--sitl
  plane:1,boat:2,sub:3` and `mix dolphin.console --sitl ...` start them.
  Everything a script does on `--sim N` it does here against the real
  autopilot's mission engine, arming checks, EKF and failsafes.

      {:ok, fleet} = Dolphin.SITL.start(2)
      fleet.sysids
      #=> [1, 2]
      Dolphin.SITL.stop(fleet)

      {:ok, mixed} = Dolphin.SITL.start(copter: 1, plane: 1, boat: 1, sub: 1)

  Each airframe runs its firmware with its model and ArduPilot's parameter
  defaults for it: copter ArduCopter (`+`, `copter.parm`), plane ArduPlane
  (`plane`, `plane.parm`, RTL_AUTOLAND 2: ArduPlane refuses to arm with a
  landing sequence in its mission otherwise), rover ArduRover (`rover`,
  `rover.parm`), boat ArduRover (`motorboat`, `rover.parm` and
  `motorboat.parm`), sub ArduSub (`vectored`, `sub.parm`, its home at sea
  level: its depth is its barometer's). The copter's binary is found as
  below; the others' in `$ARDUPILOT_SITL_DIR`, else beside the copter's,
  else in `../shared/sitl/`, each with its parameter files beside it.

  Each instance gets:

    * its own temporary working directory (SITL writes `eeprom.bin`, logs and
      terrain there), removed when it stops;
    * a distinct instance number (`-I`, which shifts SITL's own ports), free
      on the whole machine: each number in use is a lock file
      (`dolphin-sitl-instance-N.lock` in the system's temporary directory,
      naming the OS process that holds it; one whose process is gone is taken
      over), so several ground stations or test runs can run SITL at once;
    * a system id (`--sysid`, 1..N unless `:first_sysid` says otherwise);
    * a home spread like the simulator's (`Dolphin.Sim.homes/2`: 30 m apart
      around the report's home, or `:home` / `:homes`);
    * `--speedup` equal to the clock's (`Dolphin.Clock.speedup/0`), so that
      "30 seconds" means the same to the autopilot and to the script;
    * `--serial0 udpclient:127.0.0.1:PORT` to the link this function opens,
      `-w` (parameters wiped back to the defaults at every start).

  The instances are stopped by `stop/1`, and with the VM: SITL exits when its
  parent process dies, and its parent is the port of a process of this VM.

  ## The binary

  `:bin`, else the `ARDUPILOT_SITL` environment variable, else the first of
  `../shared/sitl/arducopter` (beside the project) that exists. Build your own
  with ArduPilot's `./waf configure --board sitl && ./waf copter`
  (`build/sitl/bin/arducopter`). Its parameter defaults: `:defaults` (a list
  of `.parm` files; later ones win), else `copter.parm` beside the binary
  (ArduPilot's `Tools/autotest/default_params/copter.parm`). `:params` adds
  parameters on top (`%{"BATT_CAPACITY" => 500}`).

  ## Cameras

  Like the simulator's, each SITL vehicle carries a camera (`camera: false`
  for none): ArduPilot's camera library is configured (`CAM1_TYPE 1`, a
  servo-triggered camera, which SITL simulates) so that the mission items
  IMAGE_START_CAPTURE / IMAGE_STOP_CAPTURE take photos, and the vehicles are
  given the `:camera` payload (`Dolphin.Vehicles.put_payloads/2`), as SITL
  announces no camera component of its own.

  ## Charging

  SITL's battery never recharges, while the simulator's does when a vehicle
  is disarmed on the ground (0.5 % a second of clock time). So that a script
  that waits for a full battery behaves alike on both, the SITL fleet charges
  its landed, disarmed vehicles at the same rate, as a charging station would,
  by resetting the autopilot's remaining charge upwards with
  MAV_CMD_BATTERY_RESET (`charge_per_s: 0` turns that off).

  ## Pace

  Each ArduPilot runs its clock at the speed-up it was given only while the
  machine has the cores for it; a loaded machine slows it (measured on two
  cores beside other test runs: 0.43 to 0.81 of 15×). The script's time —
  every `during`, a run's `--for`, the charging — is the ground station's
  clock, which would then run ahead of the vehicles and ask of them more
  than their time allows. So, while the fleet runs, the clock follows it:
  once a second the pace of each vehicle (its `time_boot_ms` against when
  it arrived, over the last seconds) is measured and the clock's speed-up
  set to the slowest one's, never above the one asked for
  (`follow_pace: false` turns that off). Engine timers and a run's `--for`
  keep their clock-time deadline through the change.
  """

  alias Dolphin.SITL.{Charger, Error, Instance}

  @typedoc "What `start/2` started."
  @type t :: %{
          link: pid(),
          port: :inet.port_number(),
          sysids: [byte()],
          instances: [pid()],
          numbers: [non_neg_integer()],
          charger: pid() | nil,
          pace: pid() | nil
        }

  # SITL answers within a heartbeat of simulated time once it runs; starting
  # takes a few seconds of real time (loading, EKF set-up).
  @ready_timeout_ms 60_000
  @poll_ms 50
  # Instance numbers in use in this VM: -I shifts SITL's own ports.
  @instances_key {__MODULE__, :instances}

  @doc """
  Starts `count` SITL instances on a new local link and returns once the
  ground station knows every vehicle, or an error saying what failed (with
  the last lines of a failing instance's output).

  Options: `:bin`, `:defaults`, `:params` (see above), `:camera` (default true), `:first_sysid` (1),
  `:home` / `:homes` (as `Dolphin.Sim.start/1`), `:follow_pace` (default true, see "Pace"), `:charge_per_s` (charge in
  percent per second of clock time, default 0.5), `:ready_timeout_ms` (real
  time, default 60 s), `:send_to` (a function from the link's port to the
  port SITL sends to, for something standing between them such as a test's
  impairment proxy), and the link's options (`:tlog`, `:forward`).
  """
  @spec start(pos_integer() | [{atom(), pos_integer()}], keyword()) :: {:ok, t()} | {:error, Error.t()}
  def start(fleet, opts \\ [])

  def start(count, opts) when is_integer(count) and count > 0, do: start([copter: count], opts)

  def start(fleet, opts) when is_list(fleet) do
    with {:ok, airframes} <- vehicle_airframes(fleet),
         {:ok, kinds} <- find_kinds(Enum.uniq(airframes), opts),
         count = length(airframes),
         {:ok, homes} <- homes(count, opts) do
      {link_opts, opts} = Keyword.split(opts, [:tlog, :forward])
      name = {:dolphin_sitl, System.unique_integer([:positive])}

      case Dolphin.Link.connect("udpin:127.0.0.1:0", [name: name] ++ link_opts) do
        {:ok, link} ->
          port = Dolphin.Link.Connection.port(name)
          first = Keyword.get(opts, :first_sysid, 1)
          sysids = Enum.to_list(first..(first + count - 1))
          # Where SITL sends: the link, or what stands between (a test's proxy).
          send_to = Keyword.get(opts, :send_to, & &1)
          numbers = take_instances(count)
          fleet = %{link: link, port: port, sysids: sysids, instances: [], numbers: numbers, charger: nil, pace: nil}
          root = Path.join(System.tmp_dir!(), "dolphin-sitl-#{System.unique_integer([:positive])}")

          specs =
            for {{{sysid, home}, instance}, airframe} <- Enum.zip(Enum.zip(Enum.zip(sysids, homes), numbers), airframes) do
              kind = kinds[airframe]

              %{
                bin: kind.bin,
                firmware: kind.firmware,
                model: kind.model,
                defaults: kind.defaults,
                params:
                  Enum.reduce(
                    [camera_params(Keyword.get(opts, :camera, true)), failsafe_params(airframe, Dolphin.Clock.speedup()), kind.params, Map.new(Keyword.get(opts, :params, %{}))],
                    &Map.merge(&2, &1)
                  ),
                sysid: sysid,
                instance: instance,
                # A submarine's home is at the surface: ArduSub's depth is its
                # barometer's, whose surface is at sea level (a home above it
                # leaves the sub at a fixed height whatever it does).
                home: if(Dolphin.Airframe.heights(airframe) == :depth, do: %{home | alt: 0.0}, else: home),
                speedup: Dolphin.Clock.speedup(),
                gcs_port: send_to.(port),
                companion_port: Keyword.get(opts, :companion_port),
                dir: Path.join(root, "vehicle-#{sysid}")
              }
            end

          # Before the vehicles are first heard, so that the fleet knows them with it.
          if Keyword.get(opts, :camera, true), do: add_payload(sysids, :camera)
          instances = Enum.map(specs, &start_instance/1)
          fleet = %{fleet | instances: instances}
          deadline = System.monotonic_time(:millisecond) + Keyword.get(opts, :ready_timeout_ms, @ready_timeout_ms)

          case await_fleet(fleet, deadline) do
            :ok ->
              {:ok, %{fleet | charger: start_charger(sysids, Keyword.get(opts, :charge_per_s, 0.5)), pace: start_pace(sysids, Keyword.get(opts, :follow_pace, true))}}

            {:error, why} ->
              stop(fleet)
              File.rm_rf(root)
              {:error, why}
          end

        {:error, e} ->
          {:error, %Error{reason: :no_link, cause: e}}
      end
    end
  end

  @doc "Stops what `start/2` started: the instances, their link, and the ground station forgets the vehicles."
  @spec stop(t()) :: :ok
  def stop(%{link: link, sysids: sysids, instances: instances, numbers: numbers} = fleet) do
    if pid = fleet.charger, do: DynamicSupervisor.terminate_child(Dolphin.Instance.names().sitls, pid)
    if pid = Map.get(fleet, :pace), do: DynamicSupervisor.terminate_child(Dolphin.Instance.names().sitls, pid)
    # The link first: a frame still on its way would make a forgotten vehicle known again.
    Dolphin.Link.disconnect(link)
    # Each instance's process gives its number back as it ends (so does one
    # whose Dolphin.Instance stops without this call); those of instances
    # never started are given back here.
    Enum.each(instances, &DynamicSupervisor.terminate_child(Dolphin.Instance.names().sitls, &1))
    release_instances(Enum.drop(numbers, length(instances)))
    remove_payload(sysids, :camera)
    Enum.each(sysids, &Dolphin.Vehicles.forget/1)
    :ok
  end

  @doc """
  Kills one vehicle's SITL process at once (SIGKILL), as a vehicle that
  vanishes mid-flight: the ground station stops hearing it.
  """
  @spec crash(t(), byte()) :: :ok
  def crash(%{sysids: sysids, instances: instances}, sysid) do
    {_, pid} = Enum.zip(sysids, instances) |> List.keyfind(sysid, 0)
    Instance.kill(pid)
  end

  # What each airframe runs: ArduPilot's binary, its physics model, its
  # parameter defaults (ArduPilot's own files, beside the binary) and the
  # parameters we add. A plane's mission lands through a landing sequence
  # (DO_LAND_START), which ArduPlane refuses to arm with unless RTL_AUTOLAND
  # says how RTL uses it ("Arm: DO_LAND_START set and RTL_AUTOLAND
  # disabled"): 2, RTL goes to the landing sequence at once, so that a plane
  # sent home lands as its mission would.
  @kinds %{
    copter: %{firmware: "ArduCopter", binary: "arducopter", model: "+", defaults: ["copter.parm"], params: %{}},
    plane: %{firmware: "ArduPlane", binary: "arduplane", model: "plane", defaults: ["plane.parm"], params: %{"RTL_AUTOLAND" => 2}},
    rover: %{firmware: "ArduRover", binary: "ardurover", model: "rover", defaults: ["rover.parm"], params: %{}},
    boat: %{firmware: "ArduRover", binary: "ardurover", model: "motorboat", defaults: ["rover.parm", "motorboat.parm"], params: %{}},
    sub: %{firmware: "ArduSub", binary: "ardusub", model: "vectored", defaults: ["sub.parm"], params: %{}}
  }

  @doc "The airframes SITL flies here (`start/2`'s fleet): each has its firmware's binary and model."
  @spec airframes() :: [atom()]
  def airframes, do: [:copter, :plane, :rover, :boat, :sub]

  # A count of copters, or [airframe: count, ...]: one airframe per vehicle, in order.
  defp vehicle_airframes(fleet) do
    case Enum.find(fleet, fn entry -> not match?({a, n} when is_atom(a) and is_integer(n) and n > 0, entry) end) do
      nil ->
        case Enum.find(fleet, fn {airframe, _} -> not Map.has_key?(@kinds, airframe) end) do
          nil -> if fleet == [], do: {:error, %Error{reason: :no_model, detail: "an empty fleet"}}, else: {:ok, Enum.flat_map(fleet, fn {a, n} -> List.duplicate(a, n) end)}
          {airframe, _} -> {:error, %Error{reason: :no_model, detail: inspect(airframe)}}
        end

      bad ->
        {:error, %Error{reason: :no_model, detail: inspect(bad)}}
    end
  end

  # Each airframe's binary and defaults: the copter's as find_binary/1 and
  # :defaults say; the others' in $ARDUPILOT_SITL_DIR, else beside the
  # copter's binary (when one is found), else in ../shared/sitl/.
  defp find_kinds(airframes, opts) do
    Enum.reduce_while(airframes, {:ok, %{}}, fn airframe, {:ok, acc} ->
      kind = @kinds[airframe]

      found =
        with {:ok, bin} <- binary_of(airframe, opts),
             {:ok, defaults} <- defaults_of(airframe, bin, opts),
             do: {:ok, Map.merge(kind, %{bin: bin, defaults: defaults})}

      case found do
        {:ok, k} -> {:cont, {:ok, Map.put(acc, airframe, k)}}
        {:error, e} -> {:halt, {:error, %{e | firmware: kind.firmware}}}
      end
    end)
  end

  defp binary_of(:copter, opts), do: find_binary(opts)

  defp binary_of(airframe, opts) do
    name = @kinds[airframe].binary
    copter_dir = with {:ok, bin} <- find_binary(opts), do: Path.dirname(bin)
    dirs = [System.get_env("ARDUPILOT_SITL_DIR"), if(is_binary(copter_dir), do: copter_dir), Path.expand("../shared/sitl", File.cwd!())]

    case Enum.find(for(dir <- dirs, dir not in [nil, ""], do: Path.join(dir, name)), &File.regular?/1) do
      nil -> {:error, %Error{reason: :no_binary, path: name}}
      path -> if executable?(path), do: {:ok, Path.expand(path)}, else: {:error, %Error{reason: :not_executable, path: path, from: "beside the copter's"}}
    end
  end

  defp defaults_of(:copter, bin, opts), do: find_defaults(bin, opts)

  defp defaults_of(airframe, bin, _opts) do
    files = for f <- @kinds[airframe].defaults, do: Path.join(Path.dirname(bin), f)

    case Enum.reject(files, &File.regular?/1) do
      [] -> {:ok, files}
      missing -> {:error, %Error{reason: :no_defaults, path: bin, detail: Enum.map(missing, &Path.basename/1)}}
    end
  end

  @doc "Whether SITL can fly `airframe` here (a copter by default): its binary and defaults are found (what its tests check first)."
  @spec available?(atom()) :: boolean()
  def available?(airframe \\ :copter)
  def available?(:copter), do: match?({:ok, _}, find_binary())
  def available?(airframe) when is_map_key(@kinds, airframe), do: match?({:ok, _}, find_kinds([airframe], []))

  @doc """
  The SITL binary to run: `:bin`, else `$ARDUPILOT_SITL`, else
  `../shared/sitl/arducopter` beside the project when it exists.
  """
  @spec find_binary(keyword()) :: {:ok, Path.t()} | {:error, Error.t()}
  def find_binary(opts \\ []) do
    candidates = [{"--sitl-bin", opts[:bin]}, {"ARDUPILOT_SITL", System.get_env("ARDUPILOT_SITL")}, {"beside the project", default_binary()}]

    case Enum.find(candidates, fn {_, path} -> path not in [nil, ""] end) do
      {from, path} ->
        cond do
          not File.regular?(path) -> {:error, %Error{reason: :binary_missing, path: path, from: from}}
          not executable?(path) -> {:error, %Error{reason: :not_executable, path: path, from: from}}
          true -> {:ok, Path.expand(path)}
        end

      nil ->
        {:error, %Error{reason: :no_binary}}
    end
  end

  @doc false
  def default_binary do
    path = Path.expand("../shared/sitl/arducopter", File.cwd!())
    if File.exists?(path), do: path
  end

  defp executable?(path) do
    case File.stat(path) do
      {:ok, %{mode: mode}} -> Bitwise.band(mode, 0o111) != 0
      _ -> false
    end
  end

  defp find_defaults(bin, opts) do
    case opts[:defaults] do
      nil ->
        beside = Path.join(Path.dirname(bin), "copter.parm")

        if File.regular?(beside),
          do: {:ok, [beside]},
          else: {:error, %Error{reason: :no_defaults, path: bin}}

      files ->
        files = List.wrap(files) |> Enum.map(&Path.expand/1)

        case Enum.reject(files, &File.regular?/1) do
          [] -> {:ok, files}
          missing -> {:error, %Error{reason: :defaults_missing, detail: missing}}
        end
    end
  end

  defp homes(count, opts) do
    {:ok, Dolphin.Sim.homes(count, opts)}
  rescue
    e in ArgumentError -> {:error, %Error{reason: :bad_homes, detail: Exception.message(e)}}
  end

  defp start_instance(spec) do
    {:ok, pid} = DynamicSupervisor.start_child(Dolphin.Instance.names().sitls, {Instance, spec})
    pid
  end

  # Every instance answers and has booted (HEARTBEAT with MAV_STATE past BOOT:
  # before that ArduCopter refuses missions with NO_SPACE), or one exited (a
  # bad binary, option or defaults file), or time ran out.
  defp await_fleet(fleet, deadline) do
    known = Enum.filter(fleet.sysids, &Dolphin.Vehicles.ready?/1)
    logs = Enum.zip(fleet.sysids, Enum.map(fleet.instances, &Instance.log/1))

    cond do
      Enum.all?(fleet.sysids, &(&1 in known)) ->
        :ok

      failed = Enum.find(logs, fn {_, log} -> log.exit_status != nil end) ->
        {sysid, log} = failed
        {:error, %Error{reason: :exited, vehicle: sysid, detail: log.exit_status, output: log.lines}}

      System.monotonic_time(:millisecond) > deadline ->
        silent = Enum.reject(fleet.sysids, &(&1 in known))
        {_sysid, log} = List.keyfind(logs, hd(silent), 0)
        {:error, %Error{reason: :never_answered, vehicle: silent, port: fleet.port, detail: log.cmdline, output: log.lines}}

      true ->
        Process.sleep(@poll_ms)
        await_fleet(fleet, deadline)
    end
  end

  # ArduSub disarms when it has not heard the ground station for
  # FS_GCS_TIMEOUT (5 s of its own time, FS_GCS_ENABLE 2): sped up K times
  # that is 5/K s of real time, which a busy machine's scheduler can take
  # from the ground station's heartbeat. The timeout is kept at 5 s of real
  # time (at most the 120 s the parameter allows).
  defp failsafe_params(:sub, speedup), do: %{"FS_GCS_TIMEOUT" => min(round(5 * speedup), 120)}
  defp failsafe_params(_airframe, _speedup), do: %{}

  defp camera_params(true), do: %{"CAM1_TYPE" => 1}
  defp camera_params(_), do: %{}

  # Payloads the fleet gives these system ids besides their components' (in
  # the caller's instance: Dolphin.Vehicles.put_payloads/2).
  defp add_payload(sysids, payload), do: Enum.each(sysids, &Dolphin.Vehicles.put_payloads(&1, [payload | Dolphin.Vehicles.given_payloads(&1)]))

  defp remove_payload(sysids, payload), do: Enum.each(sysids, &Dolphin.Vehicles.put_payloads(&1, List.delete(Dolphin.Vehicles.given_payloads(&1), payload)))

  defp start_pace(_sysids, false), do: nil

  defp start_pace(sysids, true) do
    {:ok, pid} = DynamicSupervisor.start_child(Dolphin.Instance.names().sitls, {Dolphin.SITL.Pace, ids: sysids, speedup: Dolphin.Clock.speedup()})
    pid
  end

  defp start_charger(_sysids, rate) when rate <= 0, do: nil

  defp start_charger(sysids, rate) do
    {:ok, pid} = DynamicSupervisor.start_child(Dolphin.Instance.names().sitls, {Charger, sysids: sysids, per_s: rate})
    pid
  end

  # Instance numbers: the lowest free ones, so that -I stays small (SITL's
  # ports are 5760 + 10·I and 5501 + 10·I). Free on this machine, not only in
  # this VM: each number in use is a lock file in the system's temporary
  # directory naming the OS process that holds it, so two ground stations
  # (or two test runs) on one machine never give two instances one -I. A lock
  # whose process is gone (a VM that crashed) is taken over.
  defp take_instances(count) do
    :global.trans({@instances_key, self()}, fn ->
      used = :persistent_term.get(@instances_key, MapSet.new())
      free = Stream.iterate(0, &(&1 + 1)) |> Stream.reject(&MapSet.member?(used, &1)) |> Stream.filter(&lock_instance/1) |> Enum.take(count)
      :persistent_term.put(@instances_key, MapSet.union(used, MapSet.new(free)))
      free
    end)
  end

  @doc false
  # An instance number given back by the process that held it (Dolphin.SITL.Instance).
  @spec release_instance(non_neg_integer()) :: :ok
  def release_instance(number), do: release_instances([number])

  defp release_instances([]), do: :ok

  defp release_instances(numbers) do
    :global.trans({@instances_key, self()}, fn ->
      Enum.each(numbers, &File.rm(instance_lock(&1)))
      used = :persistent_term.get(@instances_key, MapSet.new())
      :persistent_term.put(@instances_key, MapSet.difference(used, MapSet.new(numbers)))
    end)
  end

  defp instance_lock(n), do: Path.join(Application.get_env(:dolphin, :sitl_lock_dir, System.tmp_dir!()), "dolphin-sitl-instance-#{n}.lock")

  # Held by a process that is gone: taken over (once; another taker may win the race).
  defp lock_instance(n) do
    path = instance_lock(n)
    create_lock(path) or (stale_lock?(path) and File.rm(path) == :ok and create_lock(path))
  end

  defp create_lock(path) do
    case File.open(path, [:write, :exclusive]) do
      {:ok, file} ->
        IO.write(file, System.pid())
        File.close(file)
        true

      {:error, _} ->
        false
    end
  end

  defp stale_lock?(path) do
    case File.read(path) do
      {:ok, holder} -> not os_process_alive?(String.trim(holder))
      {:error, _} -> false
    end
  end

  defp os_process_alive?(""), do: false
  # Without /proc (not Linux), a lock is taken for held: numbers are skipped, never shared.
  defp os_process_alive?(pid), do: not File.dir?("/proc/self") or File.dir?("/proc/" <> pid)
end
