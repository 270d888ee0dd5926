defmodule Dolphin.Console do
  @moduledoc """
  Helpers to watch and steer a fleet from IEx.

      $ iex -S mix dolphin.console --sim 2 --speedup 20
      iex(1)> run("examples/single_vehicle.exs")
      run 1 started: script examples/single_vehicle.exs (tasks() shows it, stop(1) stops it)
      iex(2)> takeoff(2, 20)
      vehicle 2: mode GUIDED accepted
      vehicle 2: arm accepted
      vehicle 2: take-off to 20.0 m above home accepted
      iex(3)> vehicles()
      ID  TYPE       MODE    ARMED  BATTERY  POSITION                  ALT  LINK   SEEN        TASK
       1  quadrotor  AUTO    yes       52 %  40.444436, -7.374839  394.4 m  100 %  149 ms ago  7 mission "Survey Area" (run 2)
       2  quadrotor  GUIDED  yes       84 %  40.444233, -7.375057   20.0 m  100 %  110 ms ago  -
      iex(4)> land(1)
      vehicle 1 is flying task 7 mission "Survey Area" (run 2): nothing sent. Add force: true to stop that task first (...)
      iex(5)> stop(1)
      stopping run 1 (script examples/single_vehicle.exs): its tasks stop and their vehicles hold; its end is printed when it comes
      run 1 script examples/single_vehicle.exs: stopped: its tasks were stopped, vehicles hold (after 3m 39s of clock time)

  The project's `.iex.exs` imports this module into every `iex -S mix`
  session; elsewhere, `import Dolphin.Console`. `h vehicles` (or any helper)
  shows its doc.

  Every helper prints what it did, or why it did nothing, and returns
  `IEx.dont_display_result()` (IEx prints nothing more). They refuse clearly,
  sending nothing: an id that is not a known vehicle (or run, or task), a
  vehicle that is lost, and a command to a vehicle that is flying a task of
  a run — unless told `force: true`, when they first stop that task (the
  vehicle holds; the task's parent goes on as if it had completed, so a
  script may give the vehicle its next task: stop the run or the script to
  take the vehicle over for good).

  ## Overview

    * `vehicles/0` — the fleet at a glance; `tasks/0` — the running task trees;
    * `run/2` — a script or a task in the background; `stop/1`, `stop_all/0`;
    * vehicle commands: `arm/2`, `disarm/2`, `mode/3`, `takeoff/3`, `goto/5`,
      `hold/2`, `rtl/2`, `land/2`, `upload/3`, `download/2`;
    * watching: `watch/2` (a live ticker), `messages/1` (STATUSTEXTs),
      `events/2` (the last events, `Dolphin.Telemetry`);
    * `answer/2` — answers a script's `ask`;
    * `web/2` — a live view of the fleet in the browser (`Dolphin.Web`).

  Altitudes given to `takeoff/3` and `goto/5` are metres above home (as
  QGroundControl's), unlike the script language's, which are above mean sea
  level. Times the console prints are clock times (`Dolphin.Clock`: with a
  speed-up, faster than your watch) except `watch/2`'s, which are real.

  The processes behind the helpers (`Dolphin.Console.Runs`, the event store)
  start with the application, so the helpers work in any IEx session on the
  node; the text they print comes from pure functions (tested without IEx).
  """

  alias Dolphin.{Clock, Engine, ManoeuvreError, Mission, Vehicles}
  alias Dolphin.Vehicles.Manoeuvres
  alias Dolphin.Console.{Check, Events, Format, MissionSource, Runs, Snapshot}

  @type vehicle_id :: non_neg_integer()

  @typedoc "What the helpers return: `IEx.dont_display_result()` (they print for themselves)."
  @type printed :: atom()

  # What IEx does not print (IEx.dont_display_result/0): the helpers print for themselves.
  defp done, do: IEx.dont_display_result()

  defp say(text), do: IO.puts(text)

  # --- the fleet ---------------------------------------------------------------

  @doc """
  The fleet at a glance: per vehicle its id, type, mode, whether armed,
  battery, position, altitude above home, link quality (frames received
  against sequence gaps), when it was last heard (or how long it has been
  lost) and the task it runs (or who picked it).
  """
  @spec vehicles() :: printed()
  def vehicles do
    Snapshot.vehicles() |> Snapshot.rows() |> Format.vehicles() |> say()
    done()
  end

  @doc """
  The running task trees: scripts started here, the runs (`execute`s) of
  each, and their tasks with what each is doing and, for platform tasks,
  the vehicle it flies. Ids here are what `stop/1` takes.
  """
  @spec tasks() :: printed()
  def tasks do
    work = Snapshot.work()
    say(Format.task_tree(work.groups, work.runs, work.tasks, work.states))

    for q <- Snapshot.safe(fn -> Runs.questions() end, []),
        do: say("waiting for an answer: #{if q.run, do: "run #{q.run}", else: "a script"} asks #{inspect(q.prompt)} (answer/1)")

    done()
  end

  # --- runs ----------------------------------------------------------------------

  @doc """
  Runs a script (a path) or a task (a mission, a combinator: anything a
  script could `execute`) in the background and prints its run id.

  Options: `on: ids` — the vehicles a task may use (default: every free
  vehicle; those its allocation does not take are freed at once);
  `for: ms` — stop a script after that much clock time.

  The run's end, its script's `message`s and `ask`s are printed here as
  they come.
  """
  @spec run(Path.t() | term(), keyword()) :: printed()
  def run(script_or_task, opts \\ [])

  def run(path, opts) when is_binary(path) do
    with {:ok, opts} <- Check.options(opts, [:for]),
         :ok <- if(File.regular?(path), do: :ok, else: {:error, "no such script: #{path}"}),
         {:ok, script} <- compile(path),
         {:ok, id} <- Runs.start_script(script, opts) do
      say("run #{id} started: script #{Path.relative_to_cwd(path)} (tasks() shows it, stop(#{id}) stops it)")
    else
      {:error, why} -> say("run: " <> why_text(why))
    end

    done()
  end

  def run(task, opts) do
    with {:ok, opts} <- Check.options(opts, [:on]),
         {:ok, task} <- taskable(task),
         {:ok, id} <- Runs.start_task(task, opts) do
      say("run #{id} started: #{Engine.Task.kind(task)} #{inspect(Engine.Task.label(task))} (tasks() shows it, stop(#{id}) stops it)")
    else
      {:error, why} -> say("run: " <> why_text(why))
    end

    done()
  end

  defp compile(path) do
    case Dolphin.Script.compile(path) do
      {:ok, script} -> {:ok, script}
      {:error, e} -> {:error, Dolphin.Script.Error.format(e)}
    end
  end

  defp taskable(value) do
    {:ok, Engine.Task.new!(value)}
  rescue
    _ -> {:error, "takes a script's path or a task (a mission, a combinator...), got: #{inspect(value, limit: 5)}"}
  end

  @doc """
  Stops what an id names (see `tasks/0`): a run started here (its script
  or task: tasks stop, vehicles hold), another run (its script, if any,
  goes on with its next statement), or one task (its vehicle holds; its
  parent goes on as if it had completed).
  """
  @spec stop(integer()) :: printed()
  def stop(id) when is_integer(id) do
    case Runs.stop(id) do
      {:ok, run} -> say("stopping run #{id} (#{run.label}): its tasks stop and their vehicles hold; its end is printed when it comes")
      {:error, :not_found} -> stop_other(id)
    end

    done()
  end

  def stop(other) do
    say("stop: takes the id of a run or task (an integer, as tasks() shows them), got: #{inspect(other)}")
    done()
  end

  defp stop_other(id) do
    cond do
      Enum.any?(Engine.runs(), &(&1.run == id)) ->
        :ok = Engine.stop(id, :operator)
        say("stopping run #{id}: its tasks stop and their vehicles hold (a script that ran it goes on with its next statement)")

      task = Enum.find(Engine.tasks(), &(&1.task_id == id)) ->
        :ok = Engine.stop_task(id, :operator)
        vehicle = if task.vehicle, do: "; vehicle #{task.vehicle} holds", else: ""
        say("stopping task #{Format.task_label(task)}#{vehicle}; its parent goes on as if it had completed")

      true ->
        say("stop: nothing runs with id #{id} (tasks() shows the ids)")
    end
  end

  @doc "Stops everything that runs: the scripts and tasks started here, other scripts, other runs. Vehicles hold."
  @spec stop_all() :: printed()
  def stop_all do
    work = Snapshot.work()
    console = for run <- work.console, match?({:ok, _}, Runs.stop(run.id)), do: "run #{run.id} (#{run.label})"
    scripts = for runner <- work.scripts, :ok == Dolphin.Script.stop(runner, :operator), do: "script #{inspect(runner)}"
    loose = for run <- work.loose, Engine.stop(run, :operator) == :ok, do: "run #{run}"

    case console ++ scripts ++ loose do
      [] -> say("nothing is running")
      stopped -> say("stopping " <> Enum.join(stopped, ", ") <> ": their tasks stop and their vehicles hold")
    end

    done()
  end

  @doc """
  Answers the oldest question a script asked (`ask/1` in a script run
  here); `answer(run, text)` answers that run's.
  """
  @spec answer(integer() | nil, String.Chars.t()) :: printed()
  def answer(run \\ nil, text) do
    cond do
      run != nil and not is_integer(run) ->
        say("answer: the run is an id (an integer), got: #{inspect(run)}")

      true ->
        case Runs.answer(run, to_string(text)) do
          {:ok, q} -> say("answered #{if q.run, do: "run #{q.run}", else: "a script"}'s #{inspect(q.prompt)}: #{inspect(to_string(text))}")
          {:error, :nothing_asked} -> say("answer: #{if run, do: "run #{run} is", else: "no script is"} asking anything now")
        end
    end

    done()
  end

  # --- vehicle commands ------------------------------------------------------------

  @doc """
  Arms the motors. ArduCopter does not arm in AUTO: set GUIDED first. While
  the autopilot refuses (not ready after boot), tries again for up to
  `wait:` ms of clock time (default 30 000; 0: once).
  """
  @spec arm(vehicle_id(), keyword()) :: printed()
  def arm(id, opts \\ []) do
    command(id, :control, opts, [:force, :wait], fn state, opts ->
      cond do
        state.armed -> say("vehicle #{id} is armed already")
        state.mode == :auto -> say("vehicle #{id} is in AUTO, where ArduCopter does not arm: mode(#{id}, :guided) first")
        true -> with_wait(id, opts, &finish(id, Manoeuvres.arm_when_ready(id, within: &1, report: reporter(id)), nil))
      end
    end)
  end

  # The `wait:` of arm/2 and takeoff/3, checked before anything is sent.
  defp with_wait(id, opts, fun) do
    case Check.ms(Keyword.get(opts, :wait, 30_000), :wait) do
      {:ok, wait} -> fun.(wait)
      {:error, why} -> say("vehicle #{id}: " <> why_text(why))
    end
  end

  # Prints the steps of a manoeuvre (Dolphin.Vehicles.Manoeuvres) as the
  # vehicle accepts them, and each new refusal it will try again.
  defp reporter(id, altitude \\ nil) do
    fn
      {:accepted, step} ->
        say("vehicle #{id}: #{step(step, altitude)} accepted")

      {:refused, step, e, texts, left_ms} ->
        say("vehicle #{id}: #{step(step, altitude)} refused (#{Exception.message(e)}#{news(texts)}); trying again until #{Format.duration(left_ms)} from now")
    end
  end

  # The refusal that ended a manoeuvre; the steps before it were printed.
  defp finish(_id, :ok, _altitude), do: :ok

  defp finish(id, {:error, %ManoeuvreError{} = e}, altitude) do
    step = %{"switching to GUIDED" => :guided, "arming" => :arm, "take-off" => :take_off} |> Map.get(e.action, e.action)
    say("vehicle #{id}: #{step(step, altitude)} refused: #{Exception.message(e.refusal)}#{news(e.texts)}")
    :error
  end

  defp step(:guided, _altitude), do: "mode GUIDED"
  defp step(:arm, _altitude), do: "arm"
  defp step(:take_off, altitude), do: "take-off to #{Format.metres(altitude)} above home"
  defp step(action, _altitude), do: action

  defp texts(id), do: Vehicles.status_texts(id)

  # The vehicle's STATUSTEXTs that came with an answer, as " — text; text".
  defp news([]), do: ""
  defp news(new), do: " — " <> Enum.map_join(new, "; ", &elem(&1, 1))

  @doc "Disarms the motors; refused in the air (it would fall: `land/2` lands and disarms)."
  @spec disarm(vehicle_id(), keyword()) :: printed()
  def disarm(id, opts \\ []) do
    command(id, :control, opts, [:force], fn state, _opts ->
      cond do
        not state.armed -> say("vehicle #{id} is disarmed already")
        Manoeuvres.in_air?(state) -> say("vehicle #{id} is in the air: disarming would make it fall; land(#{id}) lands it and it disarms on the ground")
        true -> result(id, "disarm", fn -> Vehicles.disarm(id) end)
      end
    end)
  end

  @doc """
  Sets the flight mode (`:guided`, `"BRAKE"`, ...). Pilot modes (LOITER,
  ALT_HOLD, POSHOLD, STABILIZE...) are refused in the air unless
  `force: true`: without RC throttle a copter sinks in them (`hold/2` holds).
  """
  @spec mode(vehicle_id(), atom() | String.t(), keyword()) :: printed()
  def mode(id, mode, opts \\ []) do
    case Check.mode(mode) do
      {:ok, mode} ->
        command(id, :control, opts, [:force], fn state, opts ->
          case Check.pilot_mode(mode, Manoeuvres.in_air?(state), opts[:force] == true) do
            :ok -> result(id, "mode #{Format.mode(mode)}", fn -> Vehicles.set_mode(id, mode) end)
            {:error, why} -> say("vehicle #{id}: " <> why_text(why))
          end
        end)

      {:error, why} ->
        say("mode: " <> why_text(why))
        done()
    end
  end

  @doc """
  Takes off to `altitude` metres above home: GUIDED, arm (retried while the
  autopilot is not ready, `wait:` as for `arm/2`), then NAV_TAKEOFF.
  """
  @spec takeoff(vehicle_id(), number(), keyword()) :: printed()
  def takeoff(id, altitude, opts \\ []) do
    case Check.altitude(altitude) do
      {:ok, alt} ->
        command(id, :control, opts, [:force, :wait], fn state, opts ->
          if Manoeuvres.in_air?(state) do
            say("vehicle #{id} is flying already (#{Format.metres(state.position[:relative_alt])} above home): goto(#{id}, lat, lon, alt) moves it")
          else
            with_wait(id, opts, &finish(id, Manoeuvres.take_off(id, alt, within: &1, report: reporter(id, alt)), alt))
          end
        end)

      {:error, why} ->
        say("takeoff: " <> why_text(why))
        done()
    end
  end

  @doc """
  Flies to a point and holds there (GUIDED, MAV_CMD_DO_REPOSITION):
  latitude and longitude in degrees, `altitude` in metres above home
  (`amsl: true`: above mean sea level). The vehicle must be in the air.
  """
  @spec goto(vehicle_id(), number(), number(), number(), keyword()) :: printed()
  def goto(id, lat, lon, altitude, opts \\ []) do
    case Check.position(lat, lon, altitude) do
      {:ok, point} ->
        command(id, :control, opts, [:force, :amsl], fn state, opts ->
          ref = if opts[:amsl], do: "AMSL", else: "above home"

          if Manoeuvres.in_air?(state) do
            result(id, "go to #{Format.position(lat, lon)} at #{Format.metres(altitude)} #{ref}", fn -> Manoeuvres.go_to(id, point, amsl: opts[:amsl]) end)
          else
            say("vehicle #{id} is not in the air: takeoff(#{id}, altitude) first")
          end
        end)

      {:error, why} ->
        say("goto: " <> why_text(why))
        done()
    end
  end

  @doc "Holds position: BRAKE, else GUIDED (never LOITER, which sinks without RC); disarms a vehicle still on the ground."
  @spec hold(vehicle_id(), keyword()) :: printed()
  def hold(id, opts \\ []) do
    command(id, :control, opts, [:force], fn state, _opts ->
      case Manoeuvres.hold(id) do
        :ok ->
          cond do
            not state.armed -> say("vehicle #{id} is disarmed: nothing to hold")
            state.mode in [:brake, :guided] -> say("vehicle #{id} holds already (#{Format.mode(state.mode)})")
            true -> say("vehicle #{id}: holding position (was #{Format.mode(state.mode)})")
          end

        {:error, e} ->
          say("vehicle #{id}: hold failed: #{Exception.message(e)}")
      end
    end)
  end

  @doc "Returns to launch (RTL: climbs to the RTL altitude, flies home, lands)."
  @spec rtl(vehicle_id(), keyword()) :: printed()
  def rtl(id, opts \\ []), do: command(id, :control, opts, [:force], fn _state, _ -> result(id, "return to launch", fn -> Vehicles.return_to_launch(id) end) end)

  @doc "Lands where the vehicle is (it disarms on the ground)."
  @spec land(vehicle_id(), keyword()) :: printed()
  def land(id, opts \\ []), do: command(id, :control, opts, [:force], fn _state, _ -> result(id, "land", fn -> Manoeuvres.land(id) end) end)

  @doc """
  Uploads a mission: a `%Dolphin.Mission{}` (one without a home gets the
  vehicle's) or a QGroundControl `.plan` file. `run(mission, on: id)` flies
  a mission as a task instead (upload, check, arm, start, follow).
  """
  @spec upload(vehicle_id(), Mission.t() | Path.t(), keyword()) :: printed()
  def upload(id, mission, opts \\ []) do
    case load_mission(mission) do
      {:ok, mission} ->
        command(id, :control, opts, [:force], fn state, _opts ->
          home = mission.home || (state.home && Dolphin.Geo.location(state.home.lat, state.home.lon, state.home.alt))

          case items(mission, home) do
            {:ok, items} ->
              case Vehicles.upload_mission(id, items) do
                :ok -> say("vehicle #{id}: mission #{inspect(mission.name)} uploaded (#{length(items)} items, home included)")
                {:error, e} -> say("vehicle #{id}: upload failed: " <> Exception.message(e))
              end

            {:error, why} ->
              say("upload: " <> why)
          end
        end)

      {:error, why} ->
        say("upload: " <> why)
        done()
    end
  end

  defp load_mission(%Mission{} = m), do: {:ok, m}

  defp load_mission(path) when is_binary(path) do
    with {:ok, json} <- File.read(path) |> file_error(path),
         {:ok, m} <- Mission.from_plan(json, name: Path.basename(path, ".plan")) |> plan_error(path),
         do: {:ok, m}
  end

  defp load_mission(other), do: {:error, "a mission is a %Dolphin.Mission{} or a .plan file's path, got: #{inspect(other, limit: 5)}"}

  defp file_error({:error, why}, path), do: {:error, "#{path}: #{:file.format_error(why)}"}
  defp file_error(ok, _path), do: ok
  defp plan_error({:error, e}, path), do: {:error, "#{path}: #{Exception.message(e)}"}
  defp plan_error(ok, _path), do: ok

  defp items(mission, home) do
    {:ok, if(home, do: Mission.to_items(mission, home: home), else: Mission.to_items(mission))}
  rescue
    e in ArgumentError -> {:error, Exception.message(e)}
  end

  @doc """
  Downloads the vehicle's mission and prints its items, and the mission as
  script source. `save: "file.plan"` writes it as a QGroundControl plan.
  """
  @spec download(vehicle_id(), keyword()) :: printed()
  def download(id, opts \\ []) do
    command(id, :link, opts, [:save], fn _state, opts ->
      case Vehicles.download_mission(id) do
        {:ok, [_home]} ->
          say("vehicle #{id} has no mission (only its home)")

        {:ok, items} ->
          say("vehicle #{id}: #{length(items) - 1} mission items (0 is home)")
          say(Format.items(items))

          case MissionSource.from_items(items, "vehicle #{id}") do
            {:ok, mission} ->
              say("\n" <> MissionSource.to_source(mission))
              if path = opts[:save], do: save_plan(mission, path)

            {:error, e} ->
              say("(not readable as a mission: #{Exception.message(e)})")
          end

        {:error, e} ->
          say("vehicle #{id}: download failed: " <> Exception.message(e))
      end
    end)
  end

  defp save_plan(mission, path) do
    case File.write(path, Mission.to_plan(mission)) do
      :ok -> say("saved as #{path}")
      {:error, why} -> say("cannot write #{path}: #{:file.format_error(why)}")
    end
  end

  # --- watching ---------------------------------------------------------------------

  @doc """
  A live ticker of one vehicle: a line per `every:` ms (default 1000, real
  time) — mode, armed, battery, position, altitude, heading, mission
  progress — and its messages as they come, until Enter is pressed or
  `timeout:` ms (default 60 000) pass. `keys: false` ignores the keyboard.
  """
  @spec watch(vehicle_id(), keyword()) :: printed()
  def watch(id, opts \\ []) do
    command(id, :link, opts, [:every, :timeout, :keys], fn state, opts ->
      every = Keyword.get(opts, :every, 1_000)
      timeout = Keyword.get(opts, :timeout, 60_000)

      if not (is_integer(every) and every > 0 and is_integer(timeout) and timeout >= 0) do
        say("watch: every: and timeout: are milliseconds, got: #{inspect(every)}, #{inspect(timeout)}")
      else
        reader = if Keyword.get(opts, :keys, true), do: key_reader()
        say("watching vehicle #{id} (#{if reader, do: "Enter stops, ", else: ""}stops by itself after #{Format.duration(timeout)})")
        start = System.monotonic_time(:millisecond)
        why = tick(id, state.status_texts, reader, start, start + timeout, every)
        if reader, do: Process.exit(reader, :kill)
        say("watch ended (#{why})")
      end
    end)
  end

  # Reads a line of the console in its own process: the watch goes on until it comes.
  defp key_reader do
    me = self()
    gl = Process.group_leader()
    spawn(fn -> send(me, {:watch_key, self(), IO.gets(gl, "")}) end)
  end

  defp tick(id, texts, reader, start, deadline, every) do
    case Vehicles.state(id) do
      {:ok, state} ->
        for {_sev, text} <- Enum.reverse(Format.new_texts(texts, state.status_texts)), do: say("        >> " <> text)
        say(Format.ticker(state, System.monotonic_time(:millisecond) - start))
        next = min(System.monotonic_time(:millisecond) + every, deadline)

        case pause(reader, next) do
          :key -> "key pressed"
          {:continue, reader} -> if next >= deadline, do: "timeout", else: tick(id, state.status_texts, reader, start, deadline, every)
        end

      {:error, _} ->
        "vehicle #{id} is gone"
    end
  end

  # Waits until `until` (monotonic ms) or a line typed on the console.
  defp pause(reader, until) do
    receive do
      {:watch_key, ^reader, line} when is_binary(line) -> :key
      # No keyboard (input closed): only the timeout ends the watch.
      {:watch_key, ^reader, _eof} -> pause(nil, until)
    after
      max(until - System.monotonic_time(:millisecond), 0) -> {:continue, reader}
    end
  end

  @doc "The vehicle's last STATUSTEXT messages (at most 20), oldest first, with their severity."
  @spec messages(vehicle_id()) :: printed()
  def messages(id) do
    command(id, :any, [], [], fn state, _ ->
      # Dolphin.Vehicles.state/1 adds :lost to the state struct.
      if Map.get(state, :lost), do: say("vehicle #{id} is lost; its last messages:")
      say(Format.messages(state.status_texts))
    end)
  end

  @doc """
  The last `n` events (default 20) of `Dolphin.Telemetry`, oldest first.
  Filters: `vehicle: id`, `run: id`, `event: name` (or a list of names).
  """
  @spec events(pos_integer(), keyword()) :: printed()
  def events(n \\ 20, opts \\ []) do
    with {:ok, n} <- Check.count(n),
         {:ok, opts} <- Check.options(opts, [:vehicle, :run, :event]) do
      names = opts[:event] && List.wrap(opts[:event])

      filter = fn e ->
        (names == nil or e.event in names) and
          (opts[:vehicle] == nil or Map.get(e, :vehicle) == opts[:vehicle] or opts[:vehicle] in List.wrap(Map.get(e, :vehicles))) and
          (opts[:run] == nil or Map.get(e, :run) == opts[:run])
      end

      case Events.last(n, filter) do
        [] -> say("no events#{if opts != [], do: " match", else: " yet"}")
        events -> say(Enum.map_join(events, "\n", &Dolphin.CLI.event_line(&1, Events.origin_ms())))
      end
    else
      {:error, why} -> say("events: " <> why_text(why))
    end

    done()
  end

  @web Dolphin.Console.Web

  @doc """
  Serves a live view of the fleet and its runs (`Dolphin.Web`: the flight
  report's page, kept up to date) on `http://127.0.0.1:PORT/` (0: a free
  port) until `web(:stop)`; the events the console remembers come first.
  Option: `bind: "0.0.0.0"` to listen on another address. One at a time.
  """
  @spec web(:inet.port_number() | :stop, keyword()) :: printed()
  def web(port_or_stop, opts \\ [])

  def web(:stop, _opts) do
    case Process.whereis(@web) do
      nil -> say("no live view to stop")
      pid ->
        Dolphin.Web.stop(pid)
        say("live view stopped")
    end

    done()
  end

  def web(port, opts) when is_integer(port) and port in 0..65_535 do
    with {:ok, opts} <- Check.options(opts, [:bind]),
         true <- is_binary(Keyword.get(opts, :bind, "")) || {:error, "bind: takes an address as text (\"0.0.0.0\"), got #{inspect(opts[:bind])}"},
         nil <- Process.whereis(@web) do
      start = [port: port, name: @web, title: "Live: the fleet", origin_ms: Events.origin_ms(), history: Events.last(1_000)] ++ opts

      case Dolphin.Web.start(start) do
        {:ok, pid} -> say("live view: #{Dolphin.Web.url(pid)} (web(:stop) stops it)")
        {:error, e} -> say("web: " <> Exception.message(e))
      end
    else
      {:error, why} -> say("web: " <> why_text(why))
      pid when is_pid(pid) -> say("a live view is already served at #{Dolphin.Web.url(pid)} (web(:stop) stops it)")
    end

    done()
  end

  def web(other, _opts) do
    say("web: give a TCP port (0..65535; 0 picks a free one) or :stop, got #{inspect(other)}")
    done()
  end

  # --- the common path of vehicle helpers -------------------------------------------

  # Checks the id and the options, stops the vehicle's task if told to force,
  # then runs `fun` with the vehicle's state.
  defp command(id, needs, opts, allowed, fun) do
    with {:ok, opts} <- Check.options(opts, allowed),
         vehicles = Snapshot.vehicles(),
         {:ok, verdict} <- Check.vehicle(id, Snapshot.known(vehicles), needs, opts[:force] == true),
         :ok <- stop_first(id, verdict),
         {:ok, state} <- Vehicles.state(id) |> gone(id) do
      fun.(state, opts)
    else
      {:error, why} -> say(why_text(why))
    end

    done()
  end

  # The checks' and the runs' errors are structs; the helpers' own reasons are words.
  defp why_text(%{__exception__: true} = e), do: Exception.message(e)
  defp why_text(why) when is_binary(why), do: why

  defp gone({:ok, state}, _id), do: {:ok, state}
  defp gone(_, id), do: {:error, "vehicle #{id} went away"}

  defp stop_first(_id, :free), do: :ok

  defp stop_first(id, {:stop_first, task}) do
    say("vehicle #{id}: stopping task #{Format.task_label(task)} (run #{task.run}) first; the vehicle holds")
    _ = Engine.stop_task(task.task_id, :operator)
    # The task's stop makes the vehicle hold; bounded by the engine's stop timeout (15 s of clock time).
    deadline = System.monotonic_time(:millisecond) + Clock.to_real_ms(30_000) + 1_000
    await_gone(task.task_id, deadline)
  end

  defp await_gone(task_id, deadline) do
    cond do
      not Enum.any?(Engine.tasks(), &(&1.task_id == task_id)) -> :ok
      System.monotonic_time(:millisecond) > deadline -> {:error, "task #{task_id} did not stop in time: nothing sent"}
      true -> Process.sleep(20) == :ok and await_gone(task_id, deadline)
    end
  end

  # Runs a command or a one-command manoeuvre; says whether the vehicle
  # accepted it, with the messages it sent about it.
  defp result(id, what, fun) do
    before = texts(id)

    case fun.() do
      accepted when accepted in [:ok, {:ok, :accepted}] ->
        say("vehicle #{id}: #{what} accepted")
        :ok

      {:error, %ManoeuvreError{refusal: e, texts: said}} ->
        say("vehicle #{id}: #{what} refused: #{Exception.message(e)}#{news(said)}")
        :error

      {:error, e} ->
        say("vehicle #{id}: #{what} refused: #{Exception.message(e)}#{news(Format.new_texts(before, texts(id)))}")
        :error
    end
  end
end
