defmodule Dolphin.Console.Runs do
  @moduledoc """
  What the console runs in the background: scripts and tasks started with
  `Dolphin.Console.run/2`, and the questions their scripts ask
  (`Dolphin.Script.ask/1`) until the operator answers them.

  Each run has one worker process, linked to this server: a script's worker
  starts it (`Dolphin.Script.start/2`) and waits for its end; a task's worker
  picks the vehicles it may use, starts an engine run and waits for it. When
  a run ends, its end is printed on the console that started it (the group
  leader of the caller of `start_script/2` or `start_task/2`), as are its
  script's messages and questions.

  Scripts get console ids from the engine's id space (`Dolphin.Engine.next_ids/1`),
  and a task's id is its engine run id, so one number names one thing in
  `tasks()`, `stop/1` and the events.

  `ask/2` is what the console gives scripts as their `:ask` option; a script
  started elsewhere (`iex -S mix dolphin.run`) can be given
  `ask: &Dolphin.Console.Runs.ask/1` to be answered with `answer/1` too.
  """

  use GenServer

  alias Dolphin.{Clock, Engine, Fleet}
  alias Dolphin.Console.RunError

  @typedoc "A run of the console."
  @type run :: %{
          id: integer(),
          kind: :script | :task,
          label: String.t(),
          started_ms: integer(),
          status: :running | :stopping,
          runner: pid() | nil,
          worker: pid()
        }

  # Real time a task's worker waits for its run to start before reporting it started anyway.
  @start_wait 30_000

  @doc false
  def start_link(opts \\ []), do: GenServer.start_link(__MODULE__, opts, name: Keyword.get(opts, :name, __MODULE__))

  @doc """
  Starts a compiled script (`Dolphin.Script.compile/1`) in the background;
  options: `:for` (stop it after this much clock time, ms). `{:ok, id}`, or
  `{:error, %Dolphin.Console.RunError{}}`.
  """
  @spec start_script(Dolphin.Script.t(), keyword()) :: {:ok, integer()} | {:error, RunError.t()}
  def start_script(%Dolphin.Script{} = script, opts \\ []),
    do: GenServer.call(__MODULE__, {:start, {:script, script}, opts, Process.group_leader()}, :infinity)

  @doc """
  Starts a task (anything `Dolphin.Engine.Task.new!/1` takes: a mission, a
  combinator...) in the background on the vehicles of `on:` (ids; default:
  every available vehicle). The vehicles are picked for the run; those the
  allocation does not use are released as soon as it has started.
  `{:ok, run_id}`, or a `Dolphin.Console.RunError` saying why it could not start.
  """
  @spec start_task(term(), keyword()) :: {:ok, integer()} | {:error, RunError.t()}
  def start_task(task, opts \\ []), do: GenServer.call(__MODULE__, {:start, {:task, task}, opts, Process.group_leader()}, :infinity)

  @doc "The running runs of the console, oldest first."
  @spec list() :: [run()]
  def list, do: GenServer.call(__MODULE__, :list)

  @doc "The runs that ended (most recent first, at most 20): `%{id, label, result}`."
  @spec finished() :: [map()]
  def finished, do: GenServer.call(__MODULE__, :finished)

  @doc "Stops a run of the console (its tasks stop, vehicles hold); its end is printed when it comes."
  @spec stop(integer()) :: {:ok, run()} | {:error, :not_found}
  def stop(id), do: GenServer.call(__MODULE__, {:stop, id})

  @doc """
  Asks the operator (for `Dolphin.Script.ask/1`): prints the question on the
  console and waits until `answer/2` answers it. `run` names the asking run
  in the question (nil: none).
  """
  @spec ask(integer() | nil, String.t()) :: String.t()
  def ask(run \\ nil, prompt), do: GenServer.call(__MODULE__, {:ask, run, prompt, Process.group_leader()}, :infinity)

  @doc "The questions waiting for an answer, oldest first: `%{run, prompt}`."
  @spec questions() :: [%{run: integer() | nil, prompt: String.t()}]
  def questions, do: GenServer.call(__MODULE__, :questions)

  @doc """
  Answers the oldest question (of run `run`, if given). `{:ok, %{run, prompt}}`
  (the question answered) or `{:error, :nothing_asked}`.
  """
  @spec answer(integer() | nil, String.t()) :: {:ok, map()} | {:error, :nothing_asked}
  def answer(run \\ nil, text) when is_binary(text), do: GenServer.call(__MODULE__, {:answer, run, text})

  # --- server ---

  @impl true
  def init(_opts) do
    # Workers are linked: a worker that dies is a run that ended badly, said on the console.
    Process.flag(:trap_exit, true)
    {:ok, %{runs: %{}, starting: %{}, asks: [], finished: []}}
  end

  @impl true
  def handle_call({:start, what, opts, gl}, from, s) do
    server = self()

    {worker, id} =
      case what do
        {:script, script} ->
          id = Engine.next_ids(1)
          {spawn_link(fn -> script_worker(server, id, script, opts, gl) end), id}

        {:task, task} ->
          {spawn_link(fn -> task_worker(server, task, opts) end), nil}
      end

    label =
      case what do
        {:script, script} -> "script #{Path.relative_to_cwd(script.file)}"
        {:task, task} -> "task #{task_text(task)}"
      end

    {:noreply, put_in(s.starting[worker], %{from: from, id: id, kind: elem(what, 0), label: label, gl: gl})}
  end

  def handle_call(:list, _from, s), do: {:reply, s.runs |> Map.values() |> Enum.sort_by(& &1.id) |> Enum.map(&Map.drop(&1, [:gl])), s}
  def handle_call(:finished, _from, s), do: {:reply, s.finished, s}

  def handle_call({:stop, id}, _from, s) do
    case s.runs do
      %{^id => run} ->
        case run.kind do
          :script -> Dolphin.Script.stop(run.runner, :operator)
          :task -> Engine.stop(id, :operator)
        end

        run = %{run | status: :stopping}
        {:reply, {:ok, Map.drop(run, [:gl])}, put_in(s.runs[id], run)}

      _ ->
        {:reply, {:error, :not_found}, s}
    end
  end

  def handle_call({:ask, run, prompt, gl}, {pid, _} = from, s) do
    # The console of the run (one still starting: a script may ask before
    # its start is answered), else the asker's own output.
    starting = Enum.find(Map.values(s.starting), &(run != nil and &1.id == run))

    gl =
      cond do
        run && s.runs[run] -> s.runs[run].gl
        starting -> starting.gl
        true -> gl
      end

    who = if run, do: "run #{run} asks", else: "a script asks"
    say(gl, "#{who}: #{prompt}  (answer(\"...\") to answer)")
    ask = %{run: run, prompt: prompt, from: from, ref: Process.monitor(pid)}
    {:noreply, %{s | asks: s.asks ++ [ask]}}
  end

  def handle_call(:questions, _from, s), do: {:reply, Enum.map(s.asks, &Map.take(&1, [:run, :prompt])), s}

  def handle_call({:answer, run, text}, _from, s) do
    case Enum.split_with(s.asks, &(run == nil or &1.run == run)) do
      {[ask | _], _} ->
        Process.demonitor(ask.ref, [:flush])
        GenServer.reply(ask.from, text)
        {:reply, {:ok, Map.take(ask, [:run, :prompt])}, %{s | asks: List.delete(s.asks, ask)}}

      {[], _} ->
        {:reply, {:error, :nothing_asked}, s}
    end
  end

  @impl true
  def handle_info({:ready, worker, id, runner}, s) do
    case Map.pop(s.starting, worker) do
      {nil, _} ->
        {:noreply, s}

      {start, starting} ->
        run = %{id: id, kind: start.kind, label: start.label, started_ms: Clock.now_ms(), status: :running, runner: runner, worker: worker, gl: start.gl}
        GenServer.reply(start.from, {:ok, id})
        {:noreply, %{s | starting: starting, runs: Map.put(s.runs, id, run)}}
    end
  end

  def handle_info({:start_failed, worker, why}, s) do
    case Map.pop(s.starting, worker) do
      {nil, _} -> {:noreply, s}
      {start, starting} -> GenServer.reply(start.from, {:error, why}) && {:noreply, %{s | starting: starting}}
    end
  end

  def handle_info({:finished, worker, result}, s), do: {:noreply, ended(s, worker, result)}

  def handle_info({:EXIT, worker, reason}, s) do
    case Map.pop(s.starting, worker) do
      {nil, _} ->
        # A worker that reported its end has left already; one that did not, crashed.
        {:noreply, if(reason == :normal, do: s, else: ended(s, worker, {:crashed, reason}))}

      {start, starting} ->
        GenServer.reply(start.from, {:error, %RunError{reason: :worker_exit, detail: Dolphin.Engine.Failure.exit_words(reason)}})
        {:noreply, %{s | starting: starting}}
    end
  end

  def handle_info({:DOWN, ref, :process, _pid, _reason}, s), do: {:noreply, %{s | asks: Enum.reject(s.asks, &(&1.ref == ref))}}
  def handle_info(_other, s), do: {:noreply, s}

  defp ended(s, worker, result) do
    case Enum.find(Map.values(s.runs), &(&1.worker == worker)) do
      nil ->
        s

      run ->
        took = Dolphin.Console.Format.duration(Clock.now_ms() - run.started_ms)
        say(run.gl, "run #{run.id} #{run.label}: #{result_text(result)} (after #{took} of clock time)")
        done = %{id: run.id, label: run.label, result: result_text(result)}
        %{s | runs: Map.delete(s.runs, run.id), finished: Enum.take([done | s.finished], 20)}
    end
  end

  @doc false
  # The end of a run in words.
  @spec result_text(term()) :: String.t()
  def result_text({:ok, %{result: :done}}), do: "done"
  def result_text({:ok, %{result: :stopped}}), do: "stopped: its tasks were stopped, vehicles hold"
  def result_text({:ok, :done}), do: "done"
  def result_text({:ok, :stopped}), do: "stopped: its tasks were stopped, vehicles hold"
  def result_text({:error, %Dolphin.Script.Error{kind: :halted} = e}), do: Dolphin.Script.Error.format(e)
  def result_text({:error, %Dolphin.Script.Error{} = e}), do: "failed: " <> Dolphin.Script.Error.format(e)
  def result_text({:error, %Dolphin.Engine.Failure{} = f}), do: "failed: " <> Dolphin.Engine.Failure.message(f)
  def result_text({:error, %{__exception__: true} = e}), do: "failed: " <> Exception.message(e)
  def result_text({:crashed, reason}), do: "its console worker #{Dolphin.Engine.Failure.exit_words(reason)}"
  def result_text(other), do: inspect(other, charlists: :as_lists)

  defp task_text(task) do
    t = Dolphin.Engine.Task.new!(task)
    kind = Dolphin.Engine.Task.kind(t)
    "#{kind} #{inspect(Dolphin.Engine.Task.label(t))}"
  rescue
    _ -> inspect(task, limit: 5)
  end

  # Printing on a console that may have gone (its shell ended) is no failure.
  defp say(gl, text) do
    if is_pid(gl) and Process.alive?(gl), do: IO.puts(gl, text)
    :ok
  catch
    _, _ -> :ok
  end

  # --- workers ---

  defp script_worker(server, id, script, opts, gl) do
    output = fn text -> say(gl, "[run #{id}] #{text}") end
    {:ok, runner} = Dolphin.Script.start(script, ask: &ask(id, &1), output: output, for: opts[:for])
    send(server, {:ready, self(), id, runner})
    result = Dolphin.Script.await(runner)
    Dolphin.Script.purge(script)
    send(server, {:finished, self(), result})
  end

  defp task_worker(server, task, opts) do
    fleet = Keyword.get(opts, :fleet, Fleet)

    case if(vehicles?(task), do: choose(fleet, opts[:on]), else: {:ok, []}) do
      {:ok, []} ->
        start_run(server, fleet, task)

      {:ok, ids} ->
        case Fleet.pick(fleet, self(), id: ids, count: length(ids), timeout: 0) do
          {:ok, _set} -> start_run(server, fleet, task)
          {:error, e} -> send(server, {:start_failed, self(), %RunError{reason: :pick_failed, vehicles: ids, cause: e}})
        end

      {:error, why} ->
        send(server, {:start_failed, self(), why})
    end
  end

  defp start_run(server, fleet, task) do
    Dolphin.Events.subscribe()
    {:ok, run} = Engine.start(task, owner: self(), fleet: fleet)

    case first_sign(run) do
      :started ->
        Dolphin.Events.unsubscribe()
        flush_events()
        # The allocation is made: the vehicles it did not take are free again.
        spare = for %{vehicle: v, picked_by: me, busy: busy} <- Fleet.vehicles(fleet), me == self(), busy != run, do: v.id
        if spare != [], do: Fleet.release(fleet, self(), Dolphin.Fleet.VehicleSet.new(spare))
        send(server, {:ready, self(), run, nil})
        send(server, {:finished, self(), Engine.await(run)})

      {:ended, {:error, %Dolphin.Fleet.AllocationError{} = e}} ->
        send(server, {:start_failed, self(), %RunError{reason: :no_fit, cause: e}})

      {:ended, result} ->
        # It ended as it started (an empty sequence, say): a run all the same.
        send(server, {:ready, self(), run, nil})
        send(server, {:finished, self(), result})
    end
  end

  defp first_sign(run) do
    receive do
      {:dolphin, :events, %{run: ^run}} -> :started
      {Dolphin.Engine, ^run, result} -> {:ended, result}
    after
      @start_wait -> :started
    end
  end

  defp flush_events do
    receive do
      {:dolphin, :events, _} -> flush_events()
    after
      0 -> :ok
    end
  end

  # Whether a task has platform tasks (that need vehicles).
  defp vehicles?(task) do
    t = Dolphin.Engine.Task.new!(task)
    match?(%Dolphin.Engine.PlatformTask{}, t) or Enum.any?(Dolphin.Engine.Task.children(t), &vehicles?/1)
  end

  # The vehicles a task may use: those asked for, if they are free, else every free one.
  defp choose(fleet, on) do
    free = for %{vehicle: v, picked_by: nil, busy: nil} <- Fleet.vehicles(fleet), v.connected?, do: v.id

    case on do
      nil ->
        if free == [], do: {:error, %RunError{reason: :no_free_vehicle}}, else: {:ok, free}

      on ->
        ids = Dolphin.Fleet.VehicleSet.ids(Dolphin.Fleet.VehicleSet.new(on))

        case ids -- free do
          [] -> {:ok, ids}
          taken -> {:error, %RunError{reason: :not_free, vehicles: ids, detail: taken}}
        end
    end
  rescue
    e in ArgumentError -> {:error, %RunError{reason: :bad_vehicles, detail: Exception.message(e)}}
  end
end
