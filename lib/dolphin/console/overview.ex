defmodule Dolphin.Console.Overview do
  @moduledoc false
  # What the console shows, gathered from the live system (the vehicles'
  # states, the fleet, the engine's registry of runs and tasks, the console's
  # runs and event store) into plain data for Dolphin.Console.Format and
  # Dolphin.Console.Arguments. Read-only.

  alias Dolphin.{Clock, Engine, Fleet, Vehicles}
  alias Dolphin.Console.{EventLog, Format, Runs}

  @doc false
  # Every known vehicle: %{id, state (Dolphin.Vehicles.State, or nil for a
  # vehicle of another source), view (Dolphin.Vehicles.View, or nil), paths (Dolphin.Vehicles.paths/1),
  # fleet (%Dolphin.Vehicles.View{} or nil), picked_by, busy, task (the
  # platform task flying it, or nil)}.
  # `page`: `{number, rows}`, that page of them in id order, and how many there are in all.
  @spec vehicles() :: [map()]
  def vehicles, do: elem(vehicles(:all), 0)

  @spec vehicles(:all | {pos_integer(), pos_integer()}) :: {[map()], non_neg_integer()}
  def vehicles(page) do
    fleet = Map.new(safe(fn -> Fleet.vehicles() end, []), &{&1.vehicle.id, &1})
    leaves = for t <- Engine.tasks(), t.vehicle != nil, into: %{}, do: {t.vehicle, t}
    all = Dolphin.Vehicles.Id.sort(Enum.uniq(Vehicles.list() ++ Map.keys(fleet)))
    ids = if page == :all, do: all, else: Enum.slice(all, (elem(page, 0) - 1) * elem(page, 1), elem(page, 1))

    {vehicle_entries(ids, fleet, leaves), length(all)}
  end

  defp vehicle_entries(ids, fleet, leaves) do
    for id <- ids do
      state =
        case Vehicles.state(id) do
          {:ok, state} -> state
          _ -> nil
        end

      entry = fleet[id] || %{}
      paths = if state, do: Vehicles.paths(id), else: []
      view = if state, do: ok_or_nil(Vehicles.view(id))
      %{id: id, state: state, view: view, paths: paths, fleet: entry[:vehicle], picked_by: entry[:picked_by], busy: entry[:busy], task: leaves[id]}
    end
  end

  # Silent for longer than its timeout, as its view (or the fleet's, for a
  # vehicle of another source) says.
  defp lost?(%{view: %{connected?: connected?}}), do: not connected?
  defp lost?(%{fleet: %{connected?: connected?}}), do: not connected?
  defp lost?(_v), do: false

  defp ok_or_nil({:ok, value}), do: value
  defp ok_or_nil(_), do: nil

  @doc false
  # What Dolphin.Console.Arguments.vehicle/4 needs, by id.
  @spec known([map()], integer()) :: %{integer() => Dolphin.Console.Arguments.info()}
  def known(vehicles \\ vehicles(), now_ms \\ Clock.now_ms()) do
    Map.new(vehicles, fn v ->
      silent = if v.state && v.state.link.last_seen_ms, do: now_ms - v.state.link.last_seen_ms
      lost? = lost?(v)
      {v.id, %{mavlink?: v.state != nil, lost?: lost?, silent_ms: silent, task: v.task}}
    end)
  end

  @doc false
  # The rows of Format.vehicles/1.
  @spec rows([map()], integer(), [map()]) :: [map()]
  def rows(vehicles, now_ms \\ Clock.now_ms(), console_runs \\ safe(fn -> Runs.list() end, [])) do
    Enum.map(vehicles, fn v -> row(v, now_ms, console_runs) end)
  end

  defp row(%{state: %{} = s} = v, now_ms, console_runs) do
    pos = s.position || %{}

    %{
      id: v.id,
      type: s.type && to_string(Dolphin.Vehicles.View.class(s.type)),
      airframe: airframe(s),
      mode: s.mode,
      armed: s.armed,
      battery: s.battery,
      lat: pos[:lat],
      lon: pos[:lon],
      alt: pos[:relative_alt],
      link: Map.merge(s.link, Dolphin.Vehicles.State.link_figures(s)),
      seen_ms: s.link.last_seen_ms && now_ms - s.link.last_seen_ms,
      lost?: lost?(v),
      activity: activity(v, console_runs),
      paths: for(path <- Map.get(v, :paths, []), do: Map.put(path, :seen_ms, now_ms - path.last_heard_ms))
    }
  end

  defp row(%{fleet: f} = v, _now_ms, console_runs) do
    %{
      id: v.id,
      type: "#{f.type || "?"} (fake)",
      airframe: f.airframe && to_string(f.airframe),
      mode: f.mode,
      armed: f.armed?,
      battery: f.battery,
      lat: f.position && f.position.lat,
      lon: f.position && f.position.lon,
      alt: f.relative_altitude,
      link: nil,
      seen_ms: nil,
      lost?: not f.connected?,
      activity: activity(v, console_runs)
    }
  end

  # What flies it, or what its heartbeat says when no mission is made for that.
  defp airframe(%{type: nil}), do: nil

  defp airframe(s) do
    case Dolphin.Vehicles.View.airframe(s.type, s.autopilot) do
      nil -> "unknown (#{Format.type_name(s.type)})"
      airframe -> to_string(airframe)
    end
  end

  defp activity(v, console_runs) do
    cond do
      v.task -> "#{Format.task_label(v.task)} (run #{v.task.run})"
      v.busy -> "reserved by run #{v.busy}"
      v.picked_by -> "picked by " <> owner_text(v.picked_by, console_runs)
      true -> nil
    end
  end

  defp owner_text(pid, console_runs) do
    case owner(pid, console_runs) do
      {:console, run} -> "run #{run.id} (#{run.label})"
      {:script, _runner} -> "a script"
      :other -> inspect(pid)
    end
  end

  @doc false
  # Who owns a run or a pick: a script of the console, another script
  # (its Dolphin.Script.Runner), or something else. A script's code runs in
  # a process whose parent is its runner; a console task's owner is its worker.
  @spec owner(pid(), [map()]) :: {:console, map()} | {:script, pid()} | :other
  def owner(pid, console_runs) do
    parent = parent(pid)

    cond do
      run = Enum.find(console_runs, &(&1.worker == pid or (&1.runner != nil and &1.runner == parent))) -> {:console, run}
      parent != nil and script_runner?(parent) -> {:script, parent}
      true -> :other
    end
  end

  defp parent(pid) do
    case Process.info(pid, :parent) do
      {:parent, parent} when is_pid(parent) -> parent
      _ -> nil
    end
  end

  defp script_runner?(pid) do
    match?({Dolphin.Script.Runner, :init, _}, :proc_lib.initial_call(pid))
  catch
    _, _ -> false
  end

  @doc false
  # The running work: %{groups, runs, tasks, states, console, scripts, loose}
  # (see Format.task_tree/4); `scripts` are runner pids of scripts started
  # elsewhere, `loose` the engine runs of no script.
  @spec work() :: map()
  def work do
    console = safe(fn -> Runs.list() end, [])
    runs = Engine.runs()
    owners = Map.new(runs, &{&1.run, owner(&1.owner, console)})
    now = Clock.now_ms()

    console_groups =
      for %{kind: :script} = c <- console do
        id = c.id
        mine = for r <- runs, match?({:console, %{id: ^id}}, owners[r.run]), do: r.run
        %{text: "run #{c.id} #{c.label}", state: status(c, now), runs: mine}
      end

    others = runs |> Enum.filter(&match?({:script, _}, owners[&1.run])) |> Enum.group_by(&elem(owners[&1.run], 1))

    other_groups = for {runner, rs} <- others, do: %{text: "script #{inspect(runner)} (not started from this console)", state: nil, runs: Enum.map(rs, & &1.run)}

    task_runs = for %{kind: :task} = c <- console, into: %{}, do: {c.id, c}

    run_texts =
      Enum.map(runs, fn r ->
        case task_runs[r.run] do
          nil -> %{run: r.run, text: "run #{r.run}"}
          c -> %{run: r.run, text: "run #{r.run} #{c.label} (started from this console, #{status(c, now)})"}
        end
      end)

    %{
      groups: console_groups ++ other_groups,
      runs: run_texts,
      tasks: Engine.tasks(),
      states: safe(fn -> EventLog.task_states() end, %{}),
      console: console,
      scripts: Map.keys(others),
      loose: for(r <- runs, owners[r.run] == :other, do: r.run)
    }
  end

  defp status(%{status: :stopping}, _now), do: "stopping"
  defp status(c, now), do: "running for #{Format.duration(now - c.started_ms)}"

  @doc false
  # The console's own servers may be restarting: show what there is.
  def safe(fun, default) do
    fun.()
  catch
    :exit, _ -> default
  end
end
