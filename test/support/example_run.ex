defmodule Dolphin.Test.ExampleRun do
  @moduledoc """
  An example script run as a user runs it (`Mix.Tasks.Dolphin.Run.main/2`),
  and what tests compare of it: for each mission the script flew, in order,
  how each run of it ended and which of its items were reached; how the
  script ended; which vehicles were left disarmed.
  """

  alias Dolphin.MAVLink.Ardupilotmega.GlobalPositionInt
  alias Dolphin.MAVLink.{JSON, Tlog}
  alias Dolphin.Test.GroundStation

  import ExUnit.Assertions
  alias Mix.Tasks.Dolphin.Run

  @examples Path.expand("../../examples", __DIR__)

  @doc "In a test's setup: once it ends, its vehicles forgotten and the clock back at 1× (runs leave both)."
  def clean_up_after_test do
    ExUnit.Callbacks.on_exit(fn ->
      GroundStation.forget_vehicles()
      Dolphin.Clock.set_speedup(1)
    end)

    :ok
  end

  @doc """
  Runs `examples/NAME.exs` (or the script at NAME when it is a path ending
  in `.exs`) as `mix dolphin.run` would, with `args` (the
  vehicles: `--sim N`, `--sitl N`, `--connect ENDPOINT`, and `--speedup`),
  `--for FOR_TIME` if given, events and a .tlog written under `dir` (named
  by `label`), `io` given to `Run.main/2` (such as `sitl: [send_to: ...]`). Returns the exit code, the output, how the script ended, the
  history of its missions (`history/2`), who was disarmed at the end, and
  every event (`events`, as the events file has them).
  """
  def run(dir, name, label, args, for_time, io \\ []) do
    {script, name} = if String.ends_with?(name, ".exs"), do: {name, Path.basename(name, ".exs")}, else: {Path.join(@examples, "#{name}.exs"), name}
    events = Path.join(dir, "#{name}#{label}.jsonl")
    tlog = Path.join(dir, "#{name}#{label}.tlog")
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    bound = if for_time, do: ["--for", for_time], else: []
    argv = [script | args] ++ ["--events", events, "--tlog", tlog, "--quiet"] ++ bound
    code = Run.main(argv, [out: out, err: err] ++ io)
    GroundStation.forget_vehicles()

    all = read_events(events)

    %{
      code: code,
      output: elem(StringIO.contents(out), 1) <> elem(StringIO.contents(err), 1),
      result: all |> Enum.filter(&(&1["event"] == "script_finished")) |> List.last() |> Map.get("result"),
      history: history(all, for_time != nil),
      events: all,
      disarmed_at_end: disarmed_at_end(all),
      speedup: speedup(args),
      tlog: tlog
    }
  end

  @doc "The events of an events file (`--events`), as maps, in order."
  def read_events(path) do
    path
    |> File.read!()
    |> String.split("\n", trim: true)
    |> Enum.map(fn line ->
      {:ok, e} = JSON.decode(line)
      e
    end)
  end

  @doc """
  Runs example `name` on `count` simulated vehicles (at 25×) and on `count`
  ArduCopter SITL instances (at `sitl_speedup`), both bounded by `for_time`
  (nil: the script ends by itself), and asserts the same outcome: the exit
  status, the script's result, the histories (`assert_same_history/5`, with
  `least`), and, for a script that ends by itself, the vehicles left alike.
  """
  def assert_backends_agree(dir, {name, count, for_time, sitl_speedup, least}, opts \\ []) do
    on = fn backend, speedup -> run(dir, name, backend, [backend, "#{count}", "--speedup", "#{speedup}"], for_time) end

    # The simulator's run beside SITL's, in an instance of its own (its
    # clock at its own speed-up): SITL's is the longer wait. Not for fleets
    # of SITL instances that take the cores (`beside: false`): a relay's six
    # at 10x fell to 0.22 of their pace with it.
    {sim, sitl} =
      if Keyword.get(opts, :beside, true) do
        sim = beside(fn -> on.("--sim", 25) end)
        sitl = on.("--sitl", sitl_speedup)
        {Task.await(sim, :infinity), sitl}
      else
        {on.("--sim", 25), on.("--sitl", sitl_speedup)}
      end

    assert(sim.code == 0, sim.output)
    assert(sitl.code == 0, sitl.output <> pace_note(sitl))
    assert(sim.result == sitl.result)
    # A loaded host slows the vehicles of either (SITL's the more): fewer rounds fit in their time.
    pace = [pace(sim), pace(sitl)] |> Enum.reject(&is_nil/1) |> Enum.min(fn -> nil end)
    note = pace_note(sitl) <> if(pace, do: "\nthe slower run's vehicle 1 at #{Float.round(pace, 2)} of its speed-up", else: "")
    assert_same_history(sim, sitl, least_at_pace(least, pace), {"the simulator", "SITL"}, note)

    # A script that ends by itself leaves its vehicles alike (landed and
    # disarmed after their last landing mission, or holding).
    if for_time == nil, do: assert(sitl.disarmed_at_end == sim.disarmed_at_end)
  end

  @doc """
  Starts `fun` (a run on the simulator) in a task of its own, in a
  `Dolphin.Instance` of its own, beside what the caller runs next (a run on
  SITL, the longer wait): `Task.await(task, :infinity)` for its result.
  """
  def beside(fun), do: Task.async(fn -> in_own_instance(fun) end)

  @doc "Runs `fun` in a `Dolphin.Instance` of its own, started for it and stopped after."
  def in_own_instance(fun) do
    name = :"dolphin_run_#{System.unique_integer([:positive])}"
    {:ok, pid} = Dolphin.Instance.start_link(name: name)
    Dolphin.Instance.put(name)

    try do
      fun.()
    after
      Process.unlink(pid)
      Dolphin.Instance.stop(name)
    end
  end

  # What a task stopped by the run's --for says (Dolphin.Engine.Failure).
  @deadline Dolphin.Engine.Failure.format_reason(:deadline)

  # For each mission name, in the order they finished: how each ended and the
  # items it reached. A run ended by --for stops what flies at that moment:
  # those last tasks are not part of the history (known by their reason: a
  # stop can end well before the script does, a hold over a lossy link).
  def history(all, bounded?) do
    reached =
      for %{"event" => "task_progress", "task_id" => id, "progress" => %{"reached" => r}} <- all, r != nil, reduce: %{} do
        acc -> Map.update(acc, id, [r], fn seen -> if List.last(seen) == r, do: seen, else: seen ++ [r] end)
      end

    ending = all |> Enum.filter(&(&1["event"] == "script_finished")) |> List.last() |> Map.get("t_ms")

    all
    |> Enum.filter(&(&1["event"] == "task_finished" and &1["kind"] == "mission"))
    |> Enum.reject(&(bounded? and &1["result"] == "stopped" and (&1["reason"] == @deadline or &1["t_ms"] >= ending - 2_000)))
    # (why: a failure's reason, for the messages; never compared.)
    |> Enum.group_by(& &1["name"], &%{result: &1["result"], reached: Map.get(reached, &1["task_id"], []), why: &1["reason"]})
  end

  @doc """
  Asserts that two runs flew the same history as far as both went: each
  mission of `least` flown at least that many times on both, each run of it
  ending alike and reaching the same items (those both report: which DO
  commands ArduCopter reports reached depends on the loop they end in). `on`
  names the two runs in messages; `note` is added to a shortfall's message.
  """
  def assert_same_history(run_a, run_b, least, {on_a, on_b}, note \\ "") do
    for {mission, at_least} <- least do
      a = Map.get(run_a.history, mission, [])
      b = Map.get(run_b.history, mission, [])
      common = min(length(a), length(b))
      assert common >= at_least, "#{mission}: flown #{length(a)} time(s) on #{on_a}, #{length(b)} on #{on_b}#{note}"

      for {x, y} <- Enum.zip(Enum.take(a, common), Enum.take(b, common)) do
        assert x.result == y.result, "#{mission}: #{inspect(a)} on #{on_a}, #{inspect(b)} on #{on_b}"
        # Which DO commands (camera, jump) ArduCopter reports reached depends
        # on the loop they end in (docs/ardupilot.md): the items compared are
        # those both report.
        both = MapSet.intersection(MapSet.new(x.reached), MapSet.new(y.reached))
        {x, y} = {%{x | reached: Enum.filter(x.reached, &(&1 in both))}, %{y | reached: Enum.filter(y.reached, &(&1 in both))}}
        # Items reached: the same for a mission that ended by itself; for one
        # stopped by a condition (a battery threshold) as far as both went.
        n = if x.result == "done", do: max(length(x.reached), length(y.reached)), else: min(length(x.reached), length(y.reached))
        assert Enum.take(x.reached, n) == Enum.take(y.reached, n), "#{mission}: #{inspect(a)} on #{on_a}, #{inspect(b)} on #{on_b}"
      end
    end
  end

  # Which vehicles were disarmed when the script ended, by the order they were picked.
  defp disarmed_at_end(all) do
    picked = for %{"event" => "picked", "vehicles" => vs} <- all, v <- vs, uniq: true, do: v

    armed =
      Enum.reduce(all, %{}, fn
        %{"event" => "armed", "vehicle" => v}, acc -> Map.put(acc, v, true)
        %{"event" => "disarmed", "vehicle" => v}, acc -> Map.put(acc, v, false)
        _, acc -> acc
      end)

    Enum.map(picked, &(not Map.get(armed, &1, false)))
  end

  defp speedup(args) do
    case Enum.drop_while(args, &(&1 != "--speedup")) do
      ["--speedup", k | _] -> String.to_integer(k)
      _ -> 1
    end
  end

  # How fast a run's vehicle 1 really ran (SITL, or the simulator on a loaded
  # machine): its own clock (time_boot_ms) against the log's
  # wall-clock stamps, as a fraction of the speed-up asked for.
  def pace_note(%{speedup: k} = run) do
    case pace(run) do
      nil -> ""
      pace -> "\nvehicle 1 ran at #{Float.round(pace, 2)} of the #{k}x asked for"
    end
  end

  @doc "How fast a run's vehicle 1 really ran, as a fraction of the speed-up asked for (nil: too few reports to say)."
  def pace(%{tlog: tlog, speedup: k}) do
    {frames, _} = Tlog.read(Tlog.reader(), File.read!(tlog))
    stamps = for {us, %{sysid: 1, message: %GlobalPositionInt{time_boot_ms: t}}} <- frames, do: {us, t}

    case stamps do
      [{us0, t0} | _] when length(stamps) > 10 ->
        {us1, t1} = List.last(stamps)
        (t1 - t0) / ((us1 - us0) / 1000) / k

      _ ->
        nil
    end
  end

  @doc """
  The least each mission must have been flown on two runs whose vehicles
  ran at `pace` of the speed-up asked for (the slower of the two): as
  given at a pace of 0.9 or more; below it, as many fewer as the slower
  vehicles had time for (the script's time limits and `--for` are clock
  time), never under one.

      iex> Dolphin.Test.ExampleRun.least_at_pace(%{"Home" => 4, "Tower" => 2}, 0.87)
      %{"Home" => 3, "Tower" => 1}
      iex> Dolphin.Test.ExampleRun.least_at_pace(%{"Home" => 4}, 0.95)
      %{"Home" => 4}
  """
  def least_at_pace(least, nil), do: least
  def least_at_pace(least, pace), do: Map.new(least, fn {mission, n} -> {mission, max(1, floor(n * min(1.0, pace / 0.9)))} end)
end
