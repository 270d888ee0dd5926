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
      `events/2` (the last events, `Dolphin.Events`);
    * `answer/2` — answers a script's `ask`;
    * `web/2` — a live view of the fleet in the browser (`Dolphin.Web`).

  A vehicle is given by its id as `vehicles/0` lists it: its system id, or
  for another vehicle with a system id already in use, its name
  `"SYSID@NETWORK"` (`Dolphin.Vehicles.Id`; the first vehicle of a system id
  answers to its own such name too).

  Altitudes given to `takeoff/3` and `goto/5` are metres above home (as
  QGroundControl's), unlike the script language's, which are above mean sea
  level. Times the console prints are clock times (`Dolphin.Clock`: with a
  speed-up, faster than your watch) except `watch/2`'s, which are real.

  The processes behind the helpers (`Dolphin.Console.Runs`, the event store)
  start with the application, so the helpers work in any IEx session on the
  node; the text they print comes from pure functions (tested without IEx).
  """

  alias Dolphin.{Engine, Mission}
  alias Dolphin.Console.{Arguments, EventLog, Format, Runs, Overview, Vehicle}

  @type vehicle_id :: Dolphin.Vehicles.Id.t()

  @typedoc "What the helpers return: `IEx.dont_display_result()` (they print for themselves)."
  @type printed :: atom()

  # What IEx does not print (IEx.dont_display_result/0): the helpers print for themselves.
  defp done, do: IEx.dont_display_result()

  defp say(text), do: IO.puts(text)

  # The checks' and the runs' errors are structs.
  defp why_text(e), do: Vehicle.why_text(e)

  # --- the fleet ---------------------------------------------------------------

  @page_rows 50

  @doc """
  The fleet at a glance: per vehicle its id, type, mode, whether armed,
  battery, position, altitude above home, link quality (frames received
  against sequence gaps), when it was last heard (or how long it has been
  lost) and the task it runs (or who picked it).

  A fleet of more than #{@page_rows} is shown #{@page_rows} at a time, in id
  order: `vehicles()` the first page, `vehicles(2)` the second, ...,
  `vehicles(:all)` every one; a line under the table says which.
  """
  @spec vehicles(pos_integer() | :all) :: printed()
  def vehicles(page \\ 1)

  def vehicles(:all) do
    {entries, _count} = Overview.vehicles(:all)
    entries |> Overview.rows() |> Format.vehicles() |> say()
    done()
  end

  def vehicles(page) when is_integer(page) and page >= 1 do
    {entries, count} = Overview.vehicles({page, @page_rows})
    pages = max(div(count + @page_rows - 1, @page_rows), 1)

    cond do
      entries == [] and count > 0 -> say("no page #{page}: #{count} vehicle(s), #{pages} page(s) of #{@page_rows} (vehicles(:all) shows every one)")
      count <= @page_rows -> entries |> Overview.rows() |> Format.vehicles() |> say()
      true -> say(Format.vehicles(Overview.rows(entries)) <> "\n" <> Format.page_line(page, pages, @page_rows, count))
    end

    done()
  end

  def vehicles(other), do: say("vehicles/1 takes a page number (1, 2, ...) or :all, not #{inspect(other)}") && done()

  @doc """
  The running task trees: scripts started here, the runs (`execute`s) of
  each, and their tasks with what each is doing and, for platform tasks,
  the vehicle it flies. Ids here are what `stop/1` takes.
  """
  @spec tasks() :: printed()
  def tasks do
    work = Overview.work()
    say(Format.task_tree(work.groups, work.runs, work.tasks, work.states))

    for q <- Overview.safe(fn -> Runs.questions() end, []),
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
    with {:ok, opts} <- Arguments.options(opts, [:for]),
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
    with {:ok, opts} <- Arguments.options(opts, [:on]),
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
    work = Overview.work()
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

  # --- vehicle commands and watching (Dolphin.Console.Vehicle) ---------------------

  @doc """
  Arms the motors. ArduCopter does not arm in AUTO: set GUIDED first. While
  the autopilot refuses (not ready after boot), tries again for up to
  `wait:` ms of clock time (default 30 000; 0: once).
  """
  @spec arm(vehicle_id(), keyword()) :: printed()
  defdelegate arm(id, opts \\ []), to: Vehicle

  @doc "Disarms the motors; refused in the air (it would fall: `land/2` lands and disarms)."
  @spec disarm(vehicle_id(), keyword()) :: printed()
  defdelegate disarm(id, opts \\ []), to: Vehicle

  @doc """
  Sets the flight mode (`:guided`, `"BRAKE"`, ...). Pilot modes (LOITER,
  ALT_HOLD, POSHOLD, STABILIZE...) are refused in the air unless
  `force: true`: without RC throttle a copter sinks in them (`hold/2` holds).
  """
  @spec mode(vehicle_id(), atom() | String.t(), keyword()) :: printed()
  defdelegate mode(id, mode, opts \\ []), to: Vehicle

  @doc """
  Takes off to `altitude` metres above home: GUIDED, arm (retried while the
  autopilot is not ready, `wait:` as for `arm/2`), then NAV_TAKEOFF.
  """
  @spec takeoff(vehicle_id(), number(), keyword()) :: printed()
  defdelegate takeoff(id, altitude, opts \\ []), to: Vehicle

  @doc """
  Flies to a point and holds there (GUIDED, MAV_CMD_DO_REPOSITION):
  latitude and longitude in degrees, `altitude` in metres above home
  (`amsl: true`: above mean sea level). The vehicle must be in the air.
  """
  @spec goto(vehicle_id(), number(), number(), number(), keyword()) :: printed()
  defdelegate goto(id, lat, lon, altitude, opts \\ []), to: Vehicle

  @doc "Holds position: BRAKE, else GUIDED (never LOITER, which sinks without RC); disarms a vehicle still on the ground."
  @spec hold(vehicle_id(), keyword()) :: printed()
  defdelegate hold(id, opts \\ []), to: Vehicle

  @doc "Returns to launch (RTL: climbs to the RTL altitude, flies home, lands)."
  @spec rtl(vehicle_id(), keyword()) :: printed()
  defdelegate rtl(id, opts \\ []), to: Vehicle

  @doc "Lands where the vehicle is (it disarms on the ground)."
  @spec land(vehicle_id(), keyword()) :: printed()
  defdelegate land(id, opts \\ []), to: Vehicle

  @doc """
  Uploads a mission: a `%Dolphin.Mission{}` (one without a home gets the
  vehicle's) or a QGroundControl `.plan` file. `run(mission, on: id)` flies
  a mission as a task instead (upload, check, arm, start, follow).
  """
  @spec upload(vehicle_id(), Mission.t() | Path.t(), keyword()) :: printed()
  defdelegate upload(id, mission, opts \\ []), to: Vehicle

  @doc """
  Downloads the vehicle's mission and prints its items, and the mission as
  script source. `save: "file.plan"` writes it as a QGroundControl plan.
  """
  @spec download(vehicle_id(), keyword()) :: printed()
  defdelegate download(id, opts \\ []), to: Vehicle

  @doc """
  A live ticker of one vehicle: a line per `every:` ms (default 1000, real
  time) — mode, armed, battery, position, altitude, heading, mission
  progress — and its messages as they come, until Enter is pressed or
  `timeout:` ms (default 60 000) pass. `keys: false` ignores the keyboard.
  """
  @spec watch(vehicle_id(), keyword()) :: printed()
  defdelegate watch(id, opts \\ []), to: Vehicle

  @doc "The vehicle's last STATUSTEXT messages (at most 20), oldest first, with their severity."
  @spec messages(vehicle_id()) :: printed()
  defdelegate messages(id), to: Vehicle

  @doc """
  A parameter of the vehicle, by name (`param(1, "WPNAV_SPEED")`), as its
  type says; a name it does not have is said with the names near.
  """
  @spec param(vehicle_id(), String.t()) :: printed()
  defdelegate param(id, name), to: Vehicle

  @doc "Sets a parameter and reads it back: the value the vehicle keeps (refused: another one)."
  @spec set_param(vehicle_id(), String.t(), number()) :: printed()
  defdelegate set_param(id, name, value), to: Vehicle

  @doc """
  The vehicle's parameters whose names contain `filter` (`params(1, "FENCE")`;
  `""`: all of them, fetched whole: missing ones are asked for again by index).
  """
  @spec params(vehicle_id(), String.t()) :: printed()
  defdelegate params(id, filter \\ ""), to: Vehicle

  @doc """
  The last `n` events (default 20) of `Dolphin.Events`, oldest first.
  Filters: `vehicle: id`, `run: id`, `event: name` (or a list of names).
  """
  @spec events(pos_integer(), keyword()) :: printed()
  defdelegate events(n \\ 20, opts \\ []), to: Vehicle

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
      nil ->
        say("no live view to stop")

      pid ->
        Dolphin.Web.stop(pid)
        say("live view stopped")
    end

    done()
  end

  def web(port, opts) when is_integer(port) and port in 0..65_535 do
    with {:ok, opts} <- Arguments.options(opts, [:bind]),
         true <- is_binary(Keyword.get(opts, :bind, "")) || {:error, "bind: takes an address as text (\"0.0.0.0\"), got #{inspect(opts[:bind])}"},
         nil <- Process.whereis(@web) do
      start = [port: port, name: @web, title: "Live: the fleet", origin_ms: EventLog.origin_ms(), history: EventLog.last(1_000)] ++ opts

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
end
