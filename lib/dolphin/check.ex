defmodule Dolphin.Check do
  @moduledoc """
  The pre-flight check of a script (`mix dolphin.check`, and the first step
  of `mix dolphin.run`): before any vehicle is commanded, it says what would
  go wrong, one finding per line (`Dolphin.Check.Finding`: file:line,
  severity, what).

      {:ok, fleet} = Dolphin.Check.FleetFile.read("fleet.json")
      report = Dolphin.Check.run("examples/search_and_signal.exs", fleet: fleet)
      IO.write(Dolphin.Check.format(report))
      # examples/search_and_signal.exs:46: mission "Search east" on vehicle 1: 1397 m, 177 s, 49 % of a pack, starting with 100 %
      # ...
      Dolphin.Check.errors?(report)
      #=> false

  What is checked:

    * the script compiles (a syntax error, an unknown word);
    * it is run dry: against stand-ins for the described fleet
      (`Dolphin.Check.FleetFile`, or the vehicles of `--sim N`), on a
      virtual clock that moves to the next thing due once everything has
      reacted (so its findings do not depend on how busy the machine
      is), in an instance of its own (`Dolphin.Instance`: its stand-ins'
      views, picks and events reach no live view or event log, its picks
      claim nothing in a cluster), with the real fleet's picks and the
      engine's allocation — so a `pick` that nothing can serve, or a
      concurrent composition without enough distinct vehicles, fails as it
      would in flight, and is reported with its line and why;
    * every mission a task would fly, as it is sent (`Dolphin.Mission.to_items/2`):
      something to fly (an item after its home), positions on Earth,
      heights not below the home's ground, no item beyond `:max_distance`
      from home or `:max_height` above it, a take-off before the first
      waypoint for a vehicle on the ground, and one that climbs (ArduCopter
      takes off from the ground to at least 1 m and flies on from there: a
      take-off to no height is an error), take-off pitches of 0..90°, loiter
      radii and speeds ArduCopter takes, jumps to existing items, photos only
      on a vehicle with a camera;
    * loops that never wait: a `forever` whose body has no `execute`,
      `pause`, `pick` or `ask` (nor anything else that may wait) spins a
      processor for ever, and is an error with the loop's line;
    * energy and time: each mission's length, flight time and battery use,
      from the simulated ArduCopter's model (cruise 10 m/s, climb 2.5 m/s,
      descent 1.5 m/s, 30 A hovering times effort, a 3300 mAh pack), against
      the battery the vehicle has when the mission starts in the dry run
      (its fleet value, less what earlier missions used — so after
      `wait_for(battery(v) >= 0.9, ...)` the mission starts with what the
      condition let through); a mission whose pack would be empty is
      reported with the item where it would be, one that could not come
      back home too.

  Stand-in flights drain the battery as estimated, so conditions such as
  `until(survey, battery(v) < 0.3)` end them as they would in flight. What
  the dry run cannot decide (a condition never met with the fleet's values,
  a script still running at the horizon, an `ask`, which the dry run answers
  with nothing) is a note, not an error.

  Options of `run/2`: `:fleet` (the vehicles, as `Dolphin.Check.FleetFile`
  gives them; default one camera-carrying UAV per `:sim`, default 1, at
  the simulator's home), `:max_distance` (metres from home, default 12,000),
  `:max_height` (metres above home, default 500: the report's scenarios fly
  380 m above home and survey up to 10 km away), `:max_depth` (how deep a
  submarine is sent, metres below the surface, default 100: a BlueROV2's
  rating), `:horizon_ms` (clock
  time the dry run may last, default an hour), `:energy` (the severity of a
  pack that would run empty: `:error`, the default, or `:warning` — what
  `mix dolphin.run` uses for simulated vehicles, which fly on at 0 %).
  """

  alias Dolphin.Check.{Finding, Recorder, Source}
  alias Dolphin.Fleet.FakeSource
  alias Dolphin.Vehicles.View

  defstruct file: nil, findings: [], missions: []

  @typedoc """
  A check's report: its findings (errors first) and, for each mission the
  dry run started, its estimate — `mission` (name), `vehicle`, `line`,
  `length_m`, `time_s`, `battery_used` (fraction of a pack),
  `battery_start` (the charge it started with), `ending` (`Dolphin.Mission.ending/1`).
  """
  @type t :: %__MODULE__{file: String.t(), findings: [Finding.t()], missions: [map()]}

  @sim_home %Dolphin.Geo.Location{lat: 40.444233, lon: -7.375234, h: 820.0}
  @horizon_ms 3_600_000
  # The report's scenarios fly 380 m above home and survey up to 10 km away.
  @max_distance 12_000
  @max_height 500
  @max_depth 100

  @doc "Checks the script at `path` (see the module doc for options); the findings, errors first."
  @spec run(Path.t(), keyword()) :: t()
  def run(path, opts \\ []) do
    case Dolphin.Script.compile(path) do
      {:ok, script} ->
        try do
          check_script(script, opts)
        after
          Dolphin.Script.purge(script)
        end

      {:error, e} ->
        %__MODULE__{file: path, findings: [%Finding{severity: :error, kind: :compile, file: e.file, line: e.line, message: e.message}]}
    end
  end

  @doc """
  Checks a script compiled already (`Dolphin.Script.compile/1`: `mix
  dolphin.run` checks the script it is about to fly, compiled once); the
  caller purges it. Options as `run/2`'s.
  """
  @spec check_script(Dolphin.Script.t(), keyword()) :: t()
  def check_script(%Dolphin.Script{} = script, opts \\ []), do: in_own_instance(fn -> dry_run(script, opts) end)

  @doc """
  The stand-in fleet of `--sim N` (N copters) or `--sitl plane:1,boat:2`
  (airframes and counts, in system id order): each with a camera, full, on
  the ground (or the surface) at the simulator's home, or at `home`
  (`{lat, lon, alt}`, as `--home` gives it).
  """
  @spec sim_fleet(pos_integer() | [{atom(), pos_integer()} | {atom(), pos_integer(), [atom()]}], {number(), number(), number()} | nil) :: [Dolphin.Check.FleetFile.vehicle()]
  def sim_fleet(fleet, home \\ nil)
  def sim_fleet(n, home) when is_integer(n), do: sim_fleet([copter: n], home)

  def sim_fleet(fleet, home) when is_list(fleet) do
    airframes =
      Enum.flat_map(fleet, fn
        {airframe, n} -> List.duplicate(airframe, n)
        {airframe, n, _sensors} -> List.duplicate(airframe, n)
      end)

    base = with {lat, lon, alt} <- home, do: %Dolphin.Geo.Location{lat: lat * 1.0, lon: lon * 1.0, h: alt * 1.0}, else: (nil -> @sim_home)
    # Where the simulator puts them (Dolphin.Sim.homes/2: a few tens of metres apart).
    spread = Dolphin.Sim.homes(length(airframes), home: %{lat: base.lat, lon: base.lon, alt: base.h})

    # Named as the ground station names the simulator's (beyond 254, "1@sim2", ...).
    for {{airframe, id}, at} <- Enum.zip(Enum.zip(airframes, Dolphin.Sim.Local.names(length(airframes))), spread) do
      at = Dolphin.Geo.location(at.lat, at.lon, at.alt)
      position = if Dolphin.Airframe.heights(airframe) == :depth, do: %{at | h: 0.0}, else: at
      %{id: id, type: View.airframe_class(airframe), airframe: airframe, payloads: [:camera], battery: 1.0, position: position, airborne?: false}
    end
  end

  @doc "Whether the report has an error."
  @spec errors?(t()) :: boolean()
  def errors?(%__MODULE__{findings: findings}), do: Enum.any?(findings, &(&1.severity == :error))

  @doc "The report as text: one line per finding, then one per mission estimate and a summary line."
  @spec format(t()) :: String.t()
  def format(%__MODULE__{} = r) do
    findings = Enum.map(r.findings, &(Finding.format(&1) <> "\n"))

    missions =
      for m <- r.missions do
        where = Enum.reject([r.file && Path.relative_to_cwd(r.file), m.line], &is_nil/1) |> Enum.join(":")
        start = if m.battery_start, do: ", starting with #{round(m.battery_start * 100)} %", else: ""
        "#{where}: mission #{inspect(m.mission)} on vehicle #{m.vehicle}: #{round(m.length_m)} m, #{round(m.time_s)} s, #{round(m.battery_used * 100)} % of a pack#{start}\n"
      end

    count = fn sev -> Enum.count(r.findings, &(&1.severity == sev)) end
    summary = "#{Path.relative_to_cwd(r.file || "script")}: #{count.(:error)} error(s), #{count.(:warning)} warning(s), #{count.(:note)} note(s); #{length(r.missions)} mission(s) checked\n"
    IO.iodata_to_binary([findings, missions, summary])
  end

  @doc "The report as a JSON-ready map (binary keys)."
  @spec to_map(t()) :: map()
  def to_map(%__MODULE__{} = r) do
    %{
      "file" => r.file,
      "ok" => not errors?(r),
      "findings" => Enum.map(r.findings, &Finding.to_map/1),
      "missions" =>
        Enum.map(r.missions, fn m ->
          %{
            "mission" => m.mission,
            "vehicle" => m.vehicle,
            "line" => m.line,
            "length_m" => Float.round(m.length_m * 1.0, 1),
            "time_s" => Float.round(m.time_s * 1.0, 1),
            "battery_used" => Float.round(m.battery_used * 1.0, 3),
            "battery_start" => m.battery_start,
            "ending" => m.ending |> elem(0) |> Atom.to_string()
          }
        end)
    }
  end

  # --- the dry run ---

  # A dry run works in an instance of its own (Dolphin.Instance), so that its
  # stand-ins' views, its picks and its script's events are nobody else's: a
  # live view or event log of the caller's instance does not show them, and
  # its picks claim nothing in a cluster. Dry runs run side by side, each with
  # its own clock (Dolphin.Check.Clock); their instances are named
  # Dolphin.Check.DryRun.1, .2, ...: the first one free, so that there are
  # never more names than dry runs that ran at once.
  @dry_run_instance Dolphin.Check.DryRun

  defp in_own_instance(fun, slot \\ 1) do
    instance = Module.concat(@dry_run_instance, Integer.to_string(slot))
    previous = Dolphin.Instance.put(instance)

    outcome =
      try do
        Dolphin.Check.Clock.within(instance, fn ->
          sup = start_dry_run_instance(instance)

          try do
            fun.()
          after
            Process.unlink(sup)
            Dolphin.Instance.stop(instance)
          end
        end)
      after
        Dolphin.Instance.put(previous)
      end

    case outcome do
      {:ok, result} -> result
      :taken -> in_own_instance(fun, slot + 1)
    end
  end

  # The instance of a dry run whose caller was killed may still be stopping.
  defp start_dry_run_instance(instance) do
    case Dolphin.Instance.start_link(name: instance) do
      {:ok, sup} ->
        sup

      {:error, {:already_started, old}} ->
        ref = Process.monitor(old)
        Process.exit(old, :shutdown)
        receive do: ({:DOWN, ^ref, _, _, _} -> start_dry_run_instance(instance))
    end
  end

  # Our vehicles too close to each other, anywhere in the dry run.
  defp separation(recorder, file, severity) do
    {timelines, asked} = Recorder.timelines(recorder)
    limits = asked || Dolphin.Separation.default_limits()
    for conflict <- Dolphin.Check.Separation.conflicts(timelines, limits), do: Dolphin.Check.Separation.finding(conflict, file, limits, severity)
  end

  defp dry_run(script, opts) do
    vehicles = Keyword.get_lazy(opts, :fleet, fn -> sim_fleet(Keyword.get(opts, :sim, 1)) end)
    limits = %{max_distance: Keyword.get(opts, :max_distance, @max_distance), max_height: Keyword.get(opts, :max_height, @max_height), max_depth: Keyword.get(opts, :max_depth, @max_depth)}
    horizon = Keyword.get(opts, :horizon_ms, @horizon_ms)
    n = System.unique_integer([:positive])
    test = :"dolphin_check_vehicles_#{n}"
    fleet_name = :"dolphin_check_fleet_#{n}"

    # Stand-ins: their discoveries and changes are no event of the real run.
    {:ok, ts} = FakeSource.start_link(name: test, events: false)
    by_id = Map.new(vehicles, &{&1.id, %{payloads: &1.payloads, home: &1.position, airborne?: &1.airborne?, airframe: Map.get(&1, :airframe, View.stand_in_airframe(&1.type))}})
    {:ok, recorder} = Recorder.start_link(%{test: test, file: script.file, limits: limits, vehicles: by_id})

    for v <- vehicles,
        do:
          FakeSource.add(test, v.id,
            type: v.type,
            airframe: Map.get(v, :airframe, View.stand_in_airframe(v.type)),
            payloads: v.payloads,
            battery: v.battery,
            position: v.position,
            relative_altitude: if(v.airborne?, do: 20.0, else: 0.0)
          )

    {:ok, fleet} = Dolphin.Fleet.start_link(name: fleet_name, source: {Source, %{test: test, recorder: recorder}}, claims: false, assume_sensors: true)

    try do
      busy = busy_loops(script)
      outcome = script_outcome(script, fleet_name, horizon, recorder)
      {findings, missions} = Recorder.results(recorder)
      separation = separation(recorder, script.file, Keyword.get(opts, :separation, :error))
      # After an `ask` (answered nil here) what the script does is not the dry run's to judge.
      asked? = Enum.any?(findings, &(&1.kind == :ask))
      # A busy loop is why a script is still running at the horizon: no note besides.
      outcome = if busy != [] and match?({:running, _}, outcome), do: {:ok, :busy}, else: outcome
      all = busy ++ energy_severity(findings, Keyword.get(opts, :energy, :error)) ++ separation ++ outcome_findings(outcome, script.file, horizon, asked?)
      %__MODULE__{file: script.file, findings: Enum.sort_by(all, &severity_rank(&1.severity)), missions: missions}
    after
      for pid <- [fleet, recorder, ts] do
        Process.unlink(pid)
        GenServer.stop(pid)
      end
    end
  end

  defp busy_loops(script) do
    for line <- Dolphin.Check.Loops.busy(script.source, script.file) do
      %Finding{
        severity: :error,
        kind: :busy_loop,
        file: script.file,
        line: line,
        message:
          "nothing in this `forever` loop waits (no `execute`, `pause`, `pick` or `ask` in it): it repeats as fast as the machine runs, " <>
            "keeping a processor busy for ever; wait in each round, e.g. `pause(seconds(1))` or `execute(wait_for(...))`"
      }
    end
  end

  defp energy_severity(findings, :error), do: findings
  defp energy_severity(findings, severity), do: Enum.map(findings, &if(&1.kind == :energy, do: %{&1 | severity: severity}, else: &1))

  defp severity_rank(:error), do: 0
  defp severity_rank(:warning), do: 1
  defp severity_rank(:note), do: 2

  # Runs the script on the check's clock until it ends or the horizon; a
  # script still running then is stopped, and where it was is a note.
  defp script_outcome(script, fleet, horizon, recorder) do
    # `ask` runs in the script's process: the script's frame in its stack is the question's line.
    ask = fn prompt ->
      note = {:note, :ask, "the script asks #{inspect(prompt)}: the dry run answered nothing (end of input), and what follows depends on the answer"}
      Recorder.problems(recorder, [note], caller_line(script.file) || Dolphin.Script.Statements.__line__())
      nil
    end

    Dolphin.Check.Clock.run(horizon, fn ->
      {:ok, pid} = Dolphin.Script.start(script, fleet: fleet, clock: Dolphin.Check.Clock, ask: ask, output: fn _ -> :ok end, platform_opts: [missions: Dolphin.Fleet.source(fleet)])

      receive do
        {Dolphin.Script, ^pid, result} ->
          result

        {Dolphin.Check.Clock, :horizon} ->
          where = code_place(pid)
          Dolphin.Script.stop(pid, :check_horizon)
          _ = Dolphin.Script.await(pid, 30_000)
          where
      end
    end)
  end

  defp caller_line(file) do
    {:current_stacktrace, stack} = Process.info(self(), :current_stacktrace)
    Enum.find_value(stack, fn {_m, _f, _a, where} -> if to_string(where[:file]) == file, do: where[:line] end)
  end

  # Where the script's code is: its line, and whether it waits in a pick
  # (the fleet's pick timeouts run on the real clock, not the check's: a
  # pick still waiting at the horizon is one the described fleet never serves).
  defp code_place(runner) do
    with %{code: code} when is_pid(code) <- :sys.get_state(runner),
         {:dictionary, dict} <- Process.info(code, :dictionary),
         {:current_stacktrace, stack} <- Process.info(code, :current_stacktrace) do
      line = Keyword.get(dict, :"$dolphin_line")
      if Enum.any?(stack, &match?({m, :pick, _, _} when m in [Dolphin.Fleet, Dolphin.Script.Statements], &1)), do: {:pick_waiting, line}, else: {:running, line}
    else
      _ -> {:running, nil}
    end
  catch
    :exit, _ -> {:running, nil}
  end

  defp outcome_findings({:ok, _summary}, _file, _horizon, _asked?), do: []

  defp outcome_findings({:pick_waiting, line}, file, _horizon, _asked?) do
    [
      %Finding{
        severity: :error,
        kind: :pick,
        file: file,
        line: line,
        message: "no vehicle of the fleet can serve this pick (#{source_line(file, line)}): none has the type, payload, id or place it asks for, or they are all taken"
      }
    ]
  end

  defp outcome_findings({:running, line}, file, horizon, _asked?) do
    [
      %Finding{
        severity: :note,
        kind: :waiting,
        file: file,
        line: line,
        message:
          "the script was still running after #{div(horizon, 60_000)} min of clock time in the dry run (a condition never met with the fleet's values, or a loop): what it did until then is checked"
      }
    ]
  end

  defp outcome_findings({:error, %Dolphin.Script.Error{} = e}, _file, _horizon, asked?) do
    {severity, kind, after_ask} =
      case e.reason do
        %Dolphin.Fleet.PickError{} -> {:error, :pick, ""}
        %Dolphin.Fleet.AllocationError{} -> {:error, :allocation, ""}
        _ when e.kind == :halted -> {:warning, :script, ""}
        _ when asked? -> {:note, :script, " (after an `ask` the dry run could not answer)"}
        _ -> {:error, :script, ""}
      end

    [%Finding{severity: severity, kind: kind, file: e.file, line: e.line, message: "in the dry run#{after_ask}: " <> e.message}]
  end

  defp source_line(file, line) do
    with true <- is_integer(line), {:ok, text} <- File.read(file), text when is_binary(text) <- text |> String.split("\n") |> Enum.at(line - 1) do
      "`" <> String.trim(text) <> "`"
    else
      _ -> "line #{inspect(line)}"
    end
  end
end
