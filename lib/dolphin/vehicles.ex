defmodule Dolphin.Vehicles do
  @moduledoc """
  The vehicles the ground station knows, one process each.

  A vehicle is discovered from its first HEARTBEAT (from any component but a
  ground station's) and gets a process under `Dolphin.Vehicles.Supervisor`,
  registered by its id (`Dolphin.Vehicles.Id`: its system id, or
  `"SYSID@NETWORK"` for another vehicle with a system id already in use,
  told apart by its autopilot's unique id). Links hand every frame to
  `route/2`, which casts it to that process and never waits. Every function
  here that takes a vehicle takes its id, or the qualified name of the
  first vehicle of a system id (`resolve/1`).

      Dolphin.Vehicles.subscribe(:all)      # {:dolphin, :vehicles, {:vehicle_discovered, 1}}, ...
      Dolphin.Vehicles.list()               # [1, 2, 3]
      Dolphin.Vehicles.view(1)              # {:ok, %Dolphin.Vehicles.View{battery: 0.86, mission: %{...}, ...}}
      Dolphin.Vehicles.subscribe(1)         # {:dolphin, {:vehicle, 1}, {:view, %Dolphin.Vehicles.View{}}}, ...
      Dolphin.Vehicles.state(1)             # {:ok, %Dolphin.Vehicles.State{...}}: the whole state, by a call (debugging)
      Dolphin.Vehicles.send_message(1, %Dolphin.MAVLink.Ardupilotmega.CommandLong{...})

  Commands (`command/3` and the helpers below) follow the MAVLink command
  protocol (`Dolphin.Vehicles.CommandProtocol`: retransmission, IN_PROGRESS)
  and return `{:ok, :accepted}` or `{:error, %Dolphin.CommandError{}}`.

  Events: `{:vehicle_discovered, id}`, `{:vehicle_lost, id}` (silent for
  longer than its timeout: 20 s of `Dolphin.Clock` time by default, set with
  `set_timeout/2`, kept exactly, or `config :dolphin, vehicle_timeout_ms:`;
  the default at a speed-up never less than min(timeout, 3 s) of real time,
  because a simulation on a busy host falls behind its speed-up),
  `{:vehicle_reconnected, id}`, `{:vehicle_forgotten, id}` (`forget/1`),
  all derived from the vehicles' views by `Dolphin.Vehicles.Views`, and per
  vehicle its views, `{:view, view}`.

  ## One owner of a vehicle's state

  A vehicle's state lives in its process and nowhere else. The process
  writes a `Dolphin.Vehicles.View` — what the fleet and the engine's
  conditions read — into `Dolphin.Vehicles.Views` each time the view
  changes, the view before the loss or reconnection event when the vehicle
  goes silent or is heard again. That table holds the latest view of each
  vehicle for anyone to read (`view/1`, `list/0`: no call to the vehicle's
  process), publishes it on the vehicle's topic `{:vehicle, id}`
  (`subscribe/1`), says when the vehicle is discovered, lost or heard again
  (topic `:vehicles`) and turns its transitions into the `Dolphin.Events`
  events of vehicles (`vehicle_discovered`, `mode_changed`, `armed`,
  `vehicle_lost`, ...). Nobody else keeps a copy to maintain: a subscriber
  takes the latest view whole, and nobody rebuilds a vehicle from its
  changes. The view carries what the ground station's readers need — the
  mission as the vehicle reports it (`mission`), its `home`, MAV_STATE,
  MAV_TYPE, autopilot and last STATUSTEXTs besides what conditions read —
  so the mission executor, the manoeuvres, `set_mode/3`, the cluster's
  station and the console's helpers read views too; `state/1`, a call to
  the vehicle's process, is for debugging and the console's listing (its
  link counters, which change with every frame, are in no view). A vehicle heard by another ground station node can be put in the
  table too: it is then listed and read here like a local one.

  ## Paths: one vehicle heard on several links

  The same system id heard on several links (two radios, a radio and a
  relay), with the same autopilot unique id, is one vehicle with several paths, one per link and, on a `udpin`
  link, per address it sends from (`Dolphin.Vehicles.Paths`; `paths/1` lists
  them, the console's `vehicles()` shows them):

    * **De-duplication.** A frame heard on one path and then again on
      another (same component, sequence number and bytes, within a second)
      is applied to the state, given to the command and mission protocols
      and counted in `State`'s `link` once; the copy still counts in its own
      path's figures. A frame heard twice on the *same* path is never taken
      for a copy, so a vehicle heard on one link is treated exactly as if
      there were no de-duplication (a reboot that restarts the sequence at
      0, a wrap, a network's duplicate are all applied). Links see every
      frame: a link's decoding counters (`Dolphin.Link.Connection.info/1`)
      and its `.tlog` count what that link received, copies included.
    * **Figures per path.** Each path has its last-heard clock time, its
      frame count, its loss from the sequence numbers seen on it, and its
      round trip and round-trip loss from a TIMESYNC sent on it once a
      second (answers are matched to their path by `ts1`).
    * **The best path.** Everything sent to the vehicle (commands and their
      retries, mission transfers, `send_message/2`, telemetry requests)
      goes on the path in use at the moment it is sent: among the paths
      heard within 1.5 s of clock time (and 200 ms of real time), the
      lowest loss, then the lowest round trip, with hysteresis (another path
      must be clearly better for 2 s to take over). When the path in use
      goes silent another takes over within 2 s of clock time; the command
      or transfer under way carries on over it, and the task flying the
      vehicle never knows. Each change is a `path_changed` event
      (`Dolphin.Events`). The view's `link` gives the figures of the path
      in use. The vehicle is lost only when every path has been silent for
      its timeout.
  """

  alias Dolphin.CommandError
  alias Dolphin.Vehicles.Id
  alias Dolphin.MAVLink.Frame
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.Ardupilotmega.Heartbeat
  alias Dolphin.PubSub
  alias Dolphin.Vehicles.Modes

  # MAV_TYPE_GCS, and MAV_AUTOPILOT_INVALID (what a ground station sends).
  @gcs_type 6
  @no_autopilot 8

  @doc "The ids of the known vehicles, ascending (system ids, then qualified names): those with a view in `Dolphin.Vehicles.Views`, and local ones not yet through their first frame."
  @spec list() :: [Id.t()]
  def list do
    Dolphin.Instance.names().registry
    |> Registry.select([{{{:vehicle, :"$1"}, :_, :_}, [], [:"$1"]}])
    |> Enum.concat(Dolphin.Vehicles.Views.ids())
    |> Enum.uniq()
    |> Enum.sort()
  end

  @doc "Whether a vehicle has been heard and has booted (`Dolphin.Vehicles.State.ready?/1`)."
  @spec ready?(Id.t()) :: boolean()
  def ready?(id) do
    case state(id) do
      {:ok, st} -> Dolphin.Vehicles.State.ready?(st)
      _ -> false
    end
  end

  @doc """
  A vehicle's latest STATUSTEXTs, newest first, as `{severity, text}` (`[]`
  for a vehicle not known); with `Dolphin.Vehicles.State.texts_since/2`, what
  it said during an exchange.
  """
  @spec status_texts(Id.t()) :: [{integer(), String.t()}]
  def status_texts(id) do
    # A vehicle of this node: its view holds what it said before any answer
    # its process gave since (it puts the view first). Another station's:
    # its view comes by way of that station, maybe after the answer, so ask
    # its process.
    reply = if whereis_local(id), do: view(id), else: state(id)

    case reply do
      {:ok, known} -> known.status_texts
      _ -> []
    end
  end

  @doc "The latest view of a vehicle (see \"One owner of a vehicle's state\"), read from `Dolphin.Vehicles.Views`."
  @spec view(Id.t()) :: {:ok, Dolphin.Vehicles.View.t()} | {:error, :unknown_vehicle}
  def view(id) do
    id = resolve(id)

    with {:error, :unknown_vehicle} <- Dolphin.Vehicles.Views.get(id) do
      # Discovered an instant ago: its process has not taken its first frame
      # (it will at once, before anything else), so it has no row yet.
      case call_vehicle(id, :view) do
        {:ok, view} -> {:ok, view}
        _ -> {:error, :unknown_vehicle}
      end
    end
  end

  @doc """
  The whole state of a vehicle, as its process folds it
  (`Dolphin.Vehicles.State`), by a call to that process: for debugging and
  the operator's console. What the rest of the ground station reads is the
  vehicle's view (`view/1`, `Dolphin.Vehicles.Views`), read without a call.
  """
  @spec state(Id.t()) :: {:ok, Dolphin.Vehicles.State.t()} | {:error, :unknown_vehicle}
  def state(id) do
    case call_vehicle(id, :state) do
      {:ok, state} -> {:ok, state}
      _ -> {:error, :unknown_vehicle}
    end
  end

  # Calls a vehicle's process: `:no_vehicle` if there is none, `:gone` if it
  # went away before answering (it may between look-up and call).
  defp call_vehicle(id, request, timeout \\ 5_000) do
    case whereis(id) do
      nil -> :no_vehicle
      pid -> call_pid(id, pid, request, timeout, 1)
    end
  end

  # A vehicle of another ground station (Dolphin.Cluster) whose node went
  # away during the call may be heard by another station: the call is made
  # once more on the route its router has now (Dolphin.Vehicles.Routes), so that a failover does not
  # fail the task that was using the vehicle.
  defp call_pid(id, pid, request, timeout, retries) do
    {:ok, GenServer.call(pid, request, timeout)}
  catch
    :exit, reason ->
      with true <- retries > 0 and node(pid) != node() and node_gone?(reason),
           new when is_pid(new) and new != pid <- Dolphin.Vehicles.Routes.reroute(id, pid) do
        call_pid(id, new, request, timeout, retries - 1)
      else
        _ -> :gone
      end
  end

  defp node_gone?({reason, {GenServer, :call, _}}), do: node_gone?(reason)
  defp node_gone?({:nodedown, _node}), do: true
  defp node_gone?(:noconnection), do: true
  defp node_gone?(_reason), do: false

  @doc """
  The paths to a vehicle (see "Paths"), the one in use first: `via` (the
  link's name and the address heard from, `t:Dolphin.Link.Connection.via/0`;
  in words with `Dolphin.Vehicles.Paths.via_text/1`), `state` (`:active`, `:standby` or `:silent`), `loss` (towards
  the ground station, from the sequence numbers; nil until measured),
  `rtt_ms` (nil until measured), `last_heard_ms` (clock time), `frames`
  (received on that path, copies included), `in_use?`. `[]` for a vehicle
  not known. For a vehicle of another ground station (`Dolphin.Cluster`),
  the paths of the station chosen to reach it.
  """
  @spec paths(Id.t()) :: [Dolphin.Vehicles.Paths.summary()]
  def paths(id) do
    case call_vehicle(id, :paths) do
      {:ok, paths} -> paths
      _ -> []
    end
  end

  @doc "Sends a message to a vehicle on the path in use."
  @spec send_message(Id.t(), struct()) :: :ok | {:error, :unknown_vehicle}
  def send_message(id, message) do
    case whereis(id) do
      nil -> {:error, :unknown_vehicle}
      pid -> GenServer.cast(pid, {:send, message})
    end
  end

  @doc "Sets after how much clock time without a frame a vehicle is lost."
  @spec set_timeout(Id.t(), pos_integer()) :: :ok | {:error, :unknown_vehicle}
  def set_timeout(id, ms) when is_integer(ms) and ms > 0 do
    id = resolve(id)
    # Kept outside the process: a restarted vehicle process keeps it.
    :ok = Dolphin.Vehicles.Settings.put_timeout(id, ms)

    case call_vehicle(id, {:set_timeout, ms}) do
      {:ok, :ok} -> :ok
      _ -> {:error, :unknown_vehicle}
    end
  end

  @doc """
  Gives vehicle `id` (a system id, or a qualified name) `payloads` besides
  those its components announce: what it carries that MAVLink cannot say (a
  side-scan sonar; `mix dolphin.run --fleet FILE` gives a fleet file's),
  replacing what was given before (`[]`: nothing). Kept for a vehicle not
  heard yet, and through its process's restarts; its view changes at once.
  """
  @spec put_payloads(Id.t(), [atom()]) :: :ok
  def put_payloads(id, payloads) when is_list(payloads) do
    unless Enum.all?(payloads, &is_atom/1), do: raise(ArgumentError, "payloads are atoms, got: #{inspect(payloads)}")
    :ok = Dolphin.Vehicles.Settings.put_payloads(id, payloads)
    if pid = whereis(id), do: GenServer.cast(pid, :settings_changed)
    :ok
  end

  @doc """
  From now on every vehicle of the instance, heard or not yet, folds the
  readings of these sensors' sources into its view (`Dolphin.Vehicles.View`,
  `sensors`): a script's `sensor` declarations. Sources already watched stay
  watched; a source declared again keeps the longest `keep` and each
  `stale_after`.
  """
  @spec watch_sensors([Dolphin.Sensors.Sensor.t()]) :: :ok
  def watch_sensors(sensors) do
    _ = Dolphin.Vehicles.Settings.declare_sensors(sensors)

    for pid <- Registry.select(Dolphin.Instance.names().registry, [{{{:vehicle, :_}, :"$1", :_}, [], [:"$1"]}]),
        do: GenServer.cast(pid, :sensors_changed)

    :ok
  end

  @doc "The payloads given to vehicle `id` with `put_payloads/2` (not its components')."
  @spec given_payloads(Id.t()) :: [atom()]
  def given_payloads(id), do: Dolphin.Vehicles.Settings.payloads(id)

  @doc """
  Subscribes the caller to one vehicle's views (`{:dolphin, {:vehicle,
  id}, {:view, view}}`, one per change), or to `:all` the fleet's
  notices (`{:dolphin, :vehicles, {:vehicle_discovered, id}}`, ...).
  """
  @spec subscribe(Id.t() | :all) :: :ok
  def subscribe(:all), do: PubSub.subscribe(:vehicles)
  def subscribe(id), do: PubSub.subscribe({:vehicle, resolve(id)})

  @doc """
  The process of a vehicle, or nil: this node's own, else its route
  (`Dolphin.Vehicles.Routes`: in a cluster of ground stations, the
  vehicle's process on the station chosen to reach it).
  """
  @spec whereis(Id.t()) :: pid() | nil
  def whereis(id), do: whereis_local(id) || Dolphin.Vehicles.Routes.get(id) || whereis_named(id)

  # The first vehicle heard with a system id, by its qualified name.
  defp whereis_named(name) when is_binary(name) do
    case resolve(name) do
      ^name -> nil
      id -> whereis(id)
    end
  end

  defp whereis_named(_id), do: nil

  @doc """
  The id of the vehicle named `name` (`Dolphin.Vehicles.Id`): `name` itself,
  or for the qualified name of the first vehicle heard with a system id,
  that system id. A name no vehicle answers to is returned as it is.
  """
  @spec resolve(Id.t()) :: Id.t()
  def resolve(name) when is_binary(name) do
    case Dolphin.Vehicles.Views.get(name) do
      {:ok, _} -> name
      _ -> Enum.find_value(Dolphin.Vehicles.Views.all(), name, &(Dolphin.Vehicles.View.named?(&1, name) && &1.id))
    end
  end

  def resolve(id), do: id

  @doc "This node's own process of a vehicle, or nil: never a route to another ground station's."
  @spec whereis_local(Id.t()) :: pid() | nil
  def whereis_local(id) do
    case Registry.lookup(Dolphin.Instance.names().registry, {:vehicle, id}) do
      [{pid, _}] -> pid
      [] -> nil
    end
  end

  @doc """
  Forgets a vehicle: its process stops and its view is deleted from
  `Dolphin.Vehicles.Views` (no "lost" event, but `{:vehicle_forgotten,
  id}`; a vehicle picked stays picked, unavailable, until released); it
  is discovered anew, with a `vehicle_discovered` event, if it speaks again.
  For vehicles known to be gone for good, such as a finished simulation's.
  """
  @spec forget(Id.t()) :: :ok
  def forget(id) do
    id = resolve(id)
    pid = whereis_local(id)
    # What was set for it is not inherited by another vehicle given its id later.
    Dolphin.Vehicles.Settings.clear(id)

    if pid, do: DynamicSupervisor.terminate_child(Dolphin.Instance.names().vehicles, pid)

    if pid == nil and Dolphin.Vehicles.Routes.get(id) do
      # A routed vehicle (another station's) is forgotten here only, by its
      # router (its station keeps it).
      Dolphin.Vehicles.Routes.forget(id)
    else
      # A vehicle put in the table from elsewhere has no process here; the
      # table says it is forgotten.
      Dolphin.Vehicles.Views.delete(id)
    end

    :ok
  end

  @typedoc "Options of a command: `:attempts`, `:ack_timeout_ms`, `:progress_timeout_ms`, `:progress_to`, `:target_component`."
  @type command_opts :: keyword()

  @doc """
  Sends a COMMAND_LONG (`MAV_CMD` number or name, e.g. `:mav_cmd_do_set_mode`)
  with up to 7 parameters and waits for the vehicle's answer.
  """
  @typedoc "A command parameter: a number, or `:nan`, `:infinity`, `:neg_infinity` (NaN is MAVLink's \"unset\", e.g. keep the current yaw)."
  @type param :: number() | :nan | :infinity | :neg_infinity

  @spec command(Id.t(), atom() | non_neg_integer(), [param()], command_opts()) :: {:ok, :accepted} | {:error, CommandError.t()}
  def command(id, command, params \\ [], opts \\ []) when length(params) <= 7 do
    params = Enum.map(params, &param!/1) ++ List.duplicate(0.0, 7 - length(params))
    run(id, command, %{params: params, int: false, frame: 0}, opts)
  end

  @doc """
  Sends a COMMAND_INT: parameters 1-4, then a position (`lat`, `lon` in
  degrees, `alt` in metres) in `frame` (default
  MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 6).
  """
  @spec command_int(Id.t(), atom() | non_neg_integer(), [param()], {number(), number(), number()}, command_opts()) ::
          {:ok, :accepted} | {:error, CommandError.t()}
  def command_int(id, command, params, {lat, lon, alt}, opts \\ []) when length(params) <= 4 do
    params = Enum.map(params, &param!/1) ++ List.duplicate(0.0, 4 - length(params))

    unless is_number(lat) and is_number(lon) and abs(lat) <= 90 and abs(lon) <= 180 and is_number(alt),
      do: raise(ArgumentError, "command_int position must be {lat, lon, alt} in degrees and metres, got: #{inspect({lat, lon, alt})}")

    position = [round(lat * 1.0e7), round(lon * 1.0e7), alt * 1.0]
    run(id, command, %{params: params ++ position, int: true, frame: Keyword.get(opts, :frame, 6)}, opts)
  end

  @doc """
  Sets parameter `name` (a string, as the autopilot names it: `"FENCE_ACTION"`)
  of vehicle `id` to `value`: `{:ok, value}` once the vehicle answers with
  it (PARAM_SET, PARAM_VALUE; sent again on silence as a command is), or
  `{:error, %Dolphin.ParamError{}}` — `:refused` when it keeps another value.
  """
  @spec set_param(Id.t(), String.t(), number(), keyword()) :: {:ok, float()} | {:error, Dolphin.ParamError.t()}
  def set_param(id, name, value, opts \\ []) when is_binary(name) and is_number(value), do: param_request(id, name, value * 1.0, opts)

  @doc "Reads parameter `name` of vehicle `id`: `{:ok, value}` or `{:error, %Dolphin.ParamError{}}`."
  @spec read_param(Id.t(), String.t(), keyword()) :: {:ok, float()} | {:error, Dolphin.ParamError.t()}
  def read_param(id, name, opts \\ []) when is_binary(name), do: param_request(id, name, nil, opts)

  @doc """
  Parameter `name` of vehicle `id` as its type says (an integer for the
  integer types: `Dolphin.Vehicles.ParamProtocol.typed/2`), read, or set
  to `value` and read back. A name the vehicle does not answer for is
  looked up in its parameter list: one it does not have is
  `{:error, %Dolphin.ParamError{result: :unknown}}`, with the names that are
  near; a value it keeps otherwise is `:refused`.
  """
  @spec param(Id.t(), String.t(), number() | nil, keyword()) :: {:ok, number()} | {:error, Dolphin.ParamError.t()}
  def param(id, name, value, opts) when is_binary(name) and (value == nil or is_number(value)) do
    case param_request(id, name, value && value * 1.0, Keyword.put(opts, :typed, true)) do
      {:error, %Dolphin.ParamError{result: :timeout} = e} -> {:error, unknown_or(e, id, name, opts)}
      reply -> reply
    end
  end

  # A name the vehicle did not answer for: one its list lacks is unknown.
  # The whole list it last gave, when it has not changed since (on a lossy
  # link fetching a thousand values again may fail where one did); else the
  # list, with its own patience (the caller's attempts were for one value).
  defp unknown_or(e, id, name, opts) do
    names =
      case call_vehicle(id, :param_names) do
        {:ok, %MapSet{} = names} ->
          names

        _none ->
          case param_list(id, Keyword.delete(opts, :attempts)) do
            {:ok, list} -> MapSet.new(list, & &1.name)
            {:error, _} -> nil
          end
      end

    cond do
      names == nil -> e
      MapSet.member?(names, name) -> e
      true -> unknown_param(id, name, Enum.sort(names))
    end
  end

  @doc false
  # A name vehicle `id`'s parameter list (`names`) lacks, with the names near.
  @spec unknown_param(Id.t(), String.t(), [String.t()]) :: Dolphin.ParamError.t()
  def unknown_param(id, name, names) do
    detail =
      case Dolphin.Sensors.near(name, names, & &1) do
        "" -> nil
        "; " <> near -> near
      end

    %Dolphin.ParamError{param: name, vehicle: id, result: :unknown, attempts: 0, detail: detail}
  end

  @doc """
  Every parameter of vehicle `id` (`Dolphin.Vehicles.ParamList`): `{:ok,
  [%{name, value, type, index}]}` in index order, values typed; the ones a
  lossy link lost asked for again by index.
  """
  @spec param_list(Id.t(), keyword()) :: {:ok, [map()]} | {:error, Dolphin.ParamError.t()}
  def param_list(id, opts \\ []) do
    gone = %Dolphin.ParamError{param: "(the list)", vehicle: id, result: :vehicle_gone, attempts: 0}

    case call_vehicle(id, {:param_list, opts}, :infinity) do
      {:ok, reply} -> reply
      :no_vehicle -> {:error, %{gone | detail: "no such vehicle"}}
      :gone -> {:error, gone}
    end
  end

  defp param_request(id, name, value, opts) do
    gone = %Dolphin.ParamError{param: name, vehicle: id, result: :vehicle_gone, asked: value, attempts: 0}
    {typed, opts} = Keyword.pop(opts, :typed, false)

    case call_vehicle(id, {:param, %{name: name, value: value, typed: typed}, opts}, :infinity) do
      {:ok, reply} -> reply
      :no_vehicle -> {:error, %{gone | detail: "no such vehicle"}}
      :gone -> {:error, gone}
    end
  end

  defp run(id, command, request, opts) do
    {:ok, number} = command_id(command)
    name = if is_atom(command), do: command, else: number

    request =
      Map.merge(request, %{
        command: number,
        target_component: Keyword.get(opts, :target_component, 1),
        progress_to: Keyword.get(opts, :progress_to)
      })

    gone = %CommandError{command: name, vehicle: id, result: :vehicle_gone, attempts: 0}

    case call_vehicle(id, {:command, request, opts}, :infinity) do
      {:ok, reply} -> reply
      :no_vehicle -> {:error, %{gone | detail: "no such vehicle"}}
      :gone -> {:error, gone}
    end
  end

  # Caller mistakes are raised here, before anything reaches a vehicle's process.
  defp param!(p) when is_number(p), do: p * 1.0
  defp param!(p) when p in [:nan, :infinity, :neg_infinity], do: p
  defp param!(p), do: raise(ArgumentError, "command parameters must be numbers, got: #{inspect(p)}")

  defp command_id(n) when is_integer(n) and n in 0..65_535, do: {:ok, n}
  defp command_id(n) when is_integer(n), do: raise(ArgumentError, "a MAV_CMD is 0..65535, got: #{n}")

  defp command_id(name) when is_atom(name) do
    case M.enum_value(:mav_cmd, name) do
      {:ok, n} -> {:ok, n}
      :error -> raise ArgumentError, "unknown MAV_CMD #{inspect(name)}"
    end
  end

  @doc "Arms the motors (`force: true` overrides pre-arm checks, as ArduPilot's magic number 21196 does)."
  def arm(id, opts \\ []), do: command(id, :mav_cmd_component_arm_disarm, [1, if(opts[:force], do: 21_196, else: 0)], opts)

  @doc "Disarms the motors."
  def disarm(id, opts \\ []), do: command(id, :mav_cmd_component_arm_disarm, [0, if(opts[:force], do: 21_196, else: 0)], opts)

  @doc """
  Sets the flight mode by name (`:guided`, `:auto`, `:brake`, `:rtl`, ... for
  ArduPilot; `:mission`, `:posctl`, ... for PX4; see `Dolphin.Vehicles.Modes`).
  """
  @spec set_mode(Id.t(), atom(), command_opts()) :: {:ok, :accepted} | {:error, CommandError.t()}
  def set_mode(id, mode, opts \\ []) do
    with {:ok, view} <- view(id),
         {:ok, number} <- mode_number(view, mode) do
      params = if is_tuple(number), do: [1, elem(number, 0), elem(number, 1)], else: [1, number]
      command(id, :mav_cmd_do_set_mode, params, opts)
    else
      {:error, :unknown_vehicle} ->
        {:error, %CommandError{command: :mav_cmd_do_set_mode, vehicle: id, result: :vehicle_gone, attempts: 0, detail: "no such vehicle"}}

      {:error, detail} ->
        {:error, %CommandError{command: :mav_cmd_do_set_mode, vehicle: id, result: :not_sent, attempts: 0, detail: detail}}
    end
  end

  defp mode_number(%{autopilot: autopilot, mav_type: type}, mode) when autopilot in [:ardupilot, :px4] do
    case Modes.number(autopilot, type, mode) do
      {:ok, n} -> {:ok, n}
      :error -> {:error, "no mode #{inspect(mode)} on this vehicle; it has #{inspect(Modes.names(autopilot, type))}"}
    end
  end

  defp mode_number(_view, mode), do: {:error, "mode #{inspect(mode)}: the vehicle's autopilot is not known yet"}

  @doc "Takes off to `altitude` metres (relative to home)."
  def takeoff(id, altitude, opts \\ []), do: command(id, :mav_cmd_nav_takeoff, [0, 0, 0, 0, 0, 0, altitude], opts)

  @doc "Lands where the vehicle is."
  def land(id, opts \\ []), do: command(id, :mav_cmd_nav_land, [], opts)

  @doc "Returns to launch."
  def return_to_launch(id, opts \\ []), do: command(id, :mav_cmd_nav_return_to_launch, [], opts)

  @doc "Starts the uploaded mission (ArduCopter switches to AUTO itself)."
  def start_mission(id, opts \\ []), do: command(id, :mav_cmd_mission_start, [0, 0], opts)

  @doc "Makes mission item `seq` the current one."
  def set_current_item(id, seq, opts \\ []), do: command(id, :mav_cmd_do_set_mission_current, [seq], opts)

  @doc "Sets home: `:current` (where the vehicle is) or `{lat, lon, alt}` (degrees, metres AMSL; sent as COMMAND_INT)."
  def set_home(id, where, opts \\ [])
  def set_home(id, :current, opts), do: command(id, :mav_cmd_do_set_home, [1], opts)
  # COMMAND_INT: latitude and longitude exact (float32 in COMMAND_LONG would cost ~0.4 m).
  def set_home(id, {lat, lon, alt}, opts),
    do: command_int(id, :mav_cmd_do_set_home, [0], {lat, lon, alt}, Keyword.put_new(opts, :frame, 0))

  @doc "Changes the speed (m/s; `type:` `:ground` (default) or `:air`)."
  def change_speed(id, speed, opts \\ []) do
    type = if opts[:type] == :air, do: 0, else: 1
    command(id, :mav_cmd_do_change_speed, [type, speed, -1], opts)
  end

  @doc "Asks for message `msgid` every `interval_us` µs (-1 stops it)."
  def set_message_interval(id, msgid, interval_us, opts \\ []),
    do: command(id, :mav_cmd_set_message_interval, [msgid, interval_us], opts)

  @doc "Reboots the autopilot."
  def reboot(id, opts \\ []), do: command(id, :mav_cmd_preflight_reboot_shutdown, [1], opts)

  @typedoc """
  Options of a mission transfer: `:mission_type` (`:mission`, `:fence`,
  `:rally`), `:progress_to`, and those of `Dolphin.Vehicles.MissionProtocol`:
  `:send_ahead` (default: for ArduPilot), `:window`, `:attempts` (timeouts in a
  row an exchange is given; default from the link's loss), `:restarts`,
  `:total_timeout_ms`.
  """
  @type mission_opts :: keyword()

  @doc """
  Uploads a mission: `MISSION_ITEM_INT` structs in order (their `seq` and
  targets are filled in; for ArduPilot item 0 is home). See
  `Dolphin.Vehicles.MissionProtocol`. `{:error, %Dolphin.MissionError{result:
  :unconfirmed}}` means every item went out but the vehicle's final
  MISSION_ACK never came: `download_mission/2` tells whether it holds the
  mission (a mission task always reads its upload back before it flies).
  """
  @spec upload_mission(Id.t(), [struct()], mission_opts()) :: :ok | {:error, Dolphin.MissionError.t()}
  def upload_mission(id, items, opts \\ []), do: transfer(id, :upload, %{items: items}, opts)

  @doc "Downloads a mission (or fence or rally list) as `MISSION_ITEM_INT` structs."
  @spec download_mission(Id.t(), mission_opts()) :: {:ok, [struct()]} | {:error, Dolphin.MissionError.t()}
  def download_mission(id, opts \\ []), do: transfer(id, :download, %{}, opts)

  @doc "Clears the vehicle's mission (or fence or rally list)."
  @spec clear_mission(Id.t(), mission_opts()) :: :ok | {:error, Dolphin.MissionError.t()}
  def clear_mission(id, opts \\ []), do: transfer(id, :clear, %{}, opts)

  defp transfer(id, operation, request, opts) do
    type = Keyword.get(opts, :mission_type, :mission)

    unless type in [:mission, :fence, :rally],
      do: raise(ArgumentError, "mission_type must be :mission, :fence or :rally, got: #{inspect(type)}")

    if operation == :upload, do: check_items!(request.items)
    request = Map.merge(request, %{operation: operation, mission_type: type, progress_to: Keyword.get(opts, :progress_to)})
    gone = %Dolphin.MissionError{operation: operation, vehicle: id, mission_type: type, result: :vehicle_gone}

    case call_vehicle(id, {:mission, request, opts}, :infinity) do
      {:ok, reply} -> reply
      :no_vehicle -> {:error, %{gone | detail: "no such vehicle"}}
      :gone -> {:error, gone}
    end
  end

  # Every item must be a MISSION_ITEM_INT that encodes (a float in x or y, an
  # out-of-range value...): said here, naming the item, not on the wire.
  defp check_items!(items) when is_list(items) do
    items
    |> Enum.with_index()
    |> Enum.each(fn
      {%M.MissionItemInt{} = item, i} ->
        try do
          Frame.encode(item)
        rescue
          e in ArgumentError -> reraise ArgumentError, "mission item #{i}: #{Exception.message(e)}", __STACKTRACE__
        end

      {other, i} ->
        raise ArgumentError, "mission item #{i} must be a %Dolphin.MAVLink.Ardupilotmega.MissionItemInt{}, got: #{inspect(other)}"
    end)
  end

  defp check_items!(other), do: raise(ArgumentError, "a mission is a list of items, got: #{inspect(other)}")

  @doc false
  # Called by links with the frames one wake-up decoded, in order, each with
  # the path it came by: as route/2 does for each, but what goes to one
  # vehicle's process goes in one message (its process wakes once for them).
  @spec route_all([{Frame.t(), term()}]) :: :ok
  def route_all([{frame, link}]), do: route(frame, link)

  def route_all(routed) do
    {by_pid, order} =
      Enum.reduce(routed, {%{}, []}, fn {%Frame{sysid: sysid} = frame, link} = one, {by_pid, order} ->
        id = Dolphin.Vehicles.Views.vehicle_on(sysid, link)

        case whereis_local(id) do
          nil ->
            # (Its process, once started, is found for the frames after this one.)
            discover(id, frame, link)
            {by_pid, order}

          pid ->
            case by_pid do
              %{^pid => frames} -> {Map.put(by_pid, pid, [one | frames]), order}
              _ -> {Map.put(by_pid, pid, [one]), [pid | order]}
            end
        end
      end)

    for pid <- Enum.reverse(order) do
      case Map.fetch!(by_pid, pid) do
        [{frame, link}] -> GenServer.cast(pid, {:frame, frame, link})
        frames -> GenServer.cast(pid, {:frames, Enum.reverse(frames)})
      end
    end

    :ok
  end

  @doc false
  # Called by links for every frame and the path it came by (a
  # Dolphin.Link.Connection.via()): cast it to its vehicle, discovering the
  # vehicle on its first HEARTBEAT from a vehicle component.
  @spec route(Frame.t(), term()) :: :ok
  def route(%Frame{sysid: sysid} = frame, link) do
    id = Dolphin.Vehicles.Views.vehicle_on(sysid, link)

    case whereis_local(id) do
      nil -> discover(id, frame, link)
      pid -> GenServer.cast(pid, {:frame, frame, link})
    end
  end

  @doc false
  # Path `via`, on which vehicle `sysid` refused to be heard because the
  # autopilot there reported unique id `uid`, not its own: the path is
  # another vehicle's — one with that system id and that unique id heard
  # elsewhere already, else a new one named by its network
  # (Dolphin.Vehicles.Id). Its frames go to that vehicle from now on (a new
  # one is discovered by its next heartbeat). Returns the vehicle's id.
  @spec heard_elsewhere(byte(), term(), non_neg_integer()) :: Dolphin.Vehicles.Id.t()
  def heard_elsewhere(sysid, via, uid) do
    # That autopilot's other paths may have been given away already, before
    # its vehicle had a view (two paths refused in one pass).
    owner =
      Dolphin.Vehicles.Views.assigned(sysid, uid) ||
        Enum.find_value(Dolphin.Vehicles.Views.all(), fn view -> if Id.sysid(view.id) == sysid and view.uid == uid, do: view.id end)

    id = owner || unused_name(sysid, via)
    :ok = Dolphin.Vehicles.Views.assign(sysid, via, id, uid)
    id
  end

  # By its network; on a named network (Dolphin.Link.Connection's :network)
  # that already has a vehicle of that system id, by its address as well.
  defp unused_name(sysid, via) do
    name = Id.qualified(sysid, via)
    if Dolphin.Vehicles.Views.owns_name?(name), do: Id.qualified_by_address(sysid, via), else: name
  end

  defp discover(id, %Frame{message: %Heartbeat{type: type, autopilot: autopilot}} = frame, link)
       when type != @gcs_type and autopilot != @no_autopilot do
    case DynamicSupervisor.start_child(Dolphin.Instance.names().vehicles, {Dolphin.Vehicles.Vehicle, {id, link, []}}) do
      # Its first view, put once the process has taken this frame, says
      # it is discovered.
      {:ok, pid} ->
        GenServer.cast(pid, {:frame, frame, link})

      {:error, {:already_started, pid}} ->
        GenServer.cast(pid, {:frame, frame, link})

      # Not now (the supervisor is restarting): the next heartbeat will do.
      _error ->
        :ok
    end
  catch
    :exit, _ -> :ok
  end

  defp discover(_id, _frame, _link), do: :ok
end
