defmodule Dolphin.Script.Runner do
  @moduledoc false
  # One process per running script, linked to its caller: it makes the
  # script's signal table and context, runs the script's code in a linked
  # process (the owner of its picks), and ends it — on completion, on `halt`
  # from any of its tasks, at the `--for` deadline, on `Dolphin.Script.stop/2`
  # or when the caller dies. Ending a script that still runs first holds its
  # code (suspended), stops its runs for the script's reason (their tasks
  # stop, vehicles hold) and waits for them, then kills the code and releases
  # its vehicles, and only then reports: the events come in that order.
  #
  # A GenServer, so that :sys.get_state/1, :sys.trace/2 and observer see a
  # running script (its state: script, code pid, context, start time).

  use GenServer

  alias Dolphin.Engine.{Context, Signals}
  alias Dolphin.Script.{Error, Statements}

  @type reply_to :: {pid(), tag :: term()}

  # The caller gets `{tag, runner, result}` when the script ends.
  @spec start_link(map(), Context.t(), keyword(), reply_to()) :: {:ok, pid()}
  def start_link(script, ctx, opts, {caller, _tag} = reply_to) when is_pid(caller) do
    # Under Dolphin.Script.Supervisor (temporary: a script is never started
    # again), and linked to the caller from init: the caller is then not the
    # runner's OTP parent, so the caller's exit arrives in handle_info like
    # any other reason to end, and the script ends in order (an exit from the
    # parent would bypass handle_info and skip stopping the tasks). The
    # supervisor's own shutdown reaches terminate/2, which ends it in order too.
    spec = %{id: __MODULE__, start: {GenServer, :start_link, [__MODULE__, {script, ctx, opts, reply_to}]}, restart: :temporary, shutdown: :infinity, modules: [__MODULE__]}
    {:ok, _pid} = DynamicSupervisor.start_child(Dolphin.Script.Supervisor, spec)
  end

  @spec stop(pid(), term()) :: :ok
  def stop(pid, reason) do
    send(pid, {:"$dolphin_script_stop", reason})
    :ok
  end

  @impl GenServer
  def init({script, base, opts, {caller, _tag} = reply_to}) do
    # Under the application's supervisor, writing where its caller does
    # (taken first, before anything could wait: Dolphin.Check.Clock knows
    # a dry run's processes by it), working in the context's instance.
    if gl = opts[:group_leader], do: Process.group_leader(self(), gl)
    Dolphin.Instance.put(base.instance)
    Process.flag(:trap_exit, true)
    Process.link(caller)
    signals = Signals.new()
    ctx = %{base | signals: signals, script: self(), owner: nil}
    me = self()
    started = ctx.clock.now_ms()

    code =
      :proc_lib.spawn_link(fn ->
        Context.put(%{ctx | owner: self()})
        send(me, {:script_done, self(), execute(script)})
      end)

    Dolphin.Events.emit(:script_started, %{script: script.file}, started)
    deadline = if ms = opts[:for], do: ctx.clock.now_ms() + ms
    if deadline, do: ctx.clock.send_after(self(), :deadline, opts[:for])
    {:ok, %{script: script, caller: caller, reply_to: reply_to, code: code, ctx: ctx, started: started, deadline: deadline}}
  end

  defp execute(script) do
    script.module.__script__()
    :ok
  rescue
    e -> {:error, :error, e, __STACKTRACE__, Statements.__line__()}
  catch
    kind, reason -> {:error, kind, reason, __STACKTRACE__, Statements.__line__()}
  end

  @impl GenServer
  def handle_info({:script_done, code, :ok}, %{code: code} = s), do: finish(s, {:ok, :done})

  def handle_info({:script_done, code, {:error, kind, reason, stack, line}}, %{code: code} = s),
    do: finish(s, {:error, error(s.script, kind, reason, stack, line)})

  # Early when the clock slowed down after the timer was set (it follows
  # SITL vehicles that fall behind): set again for what is left.
  def handle_info(:deadline, s) do
    case s.deadline - s.ctx.clock.now_ms() do
      left when left > 0 ->
        s.ctx.clock.send_after(self(), :deadline, left)
        {:noreply, s}

      _ ->
        stop_code(s, :deadline)
        finish(s, {:ok, :stopped}, :deadline)
    end
  end

  def handle_info({:"$dolphin_script_stop", reason}, s) do
    stop_code(s, reason)
    finish(s, {:ok, :stopped}, reason)
  end

  def handle_info({:"$dolphin_halt", text}, s) do
    stop_code(s, :halted)
    finish(s, {:error, %Error{kind: :halted, file: s.script.file, message: "halted: #{text}"}})
  end

  def handle_info({:EXIT, code, reason}, %{code: code} = s) do
    # Died without reporting (killed from outside). Its runs stop their
    # trees as they get its exit: the script ends after them.
    Dolphin.Engine.Run.await(for(%{owner: owner, pid: pid} <- Dolphin.Engine.runs(), owner == code, do: pid), stop_bound(s))
    finish(s, {:error, %Error{kind: :failed, file: s.script.file, message: "the script's process #{Dolphin.Engine.Failure.exit_words(reason)}", reason: reason}})
  end

  def handle_info({:EXIT, caller, _reason}, %{caller: caller} = s) do
    # Nobody waits for the result any more; the event log still tells the end.
    stop_code(s, :shutdown)
    finish(s, {:ok, :stopped}, :shutdown)
  end

  def handle_info(_other, s), do: {:noreply, s}

  # The application shuts down (the supervisor's exit; a script that ends by
  # itself stops with :normal): the script ends as an operator's stop does,
  # its tasks stopped first and its end reported, each wait bounded by
  # stop_bound/1.
  @impl GenServer
  def terminate(reason, s) when reason == :shutdown or (is_tuple(reason) and elem(reason, 0) == :shutdown) do
    stop_code(s, :shutdown)
    finish(s, {:ok, :stopped}, :shutdown)
    # The caller has its answer; the shutdown is not its end.
    Process.unlink(s.caller)
    :ok
  end

  def terminate(_reason, _s), do: :ok

  # Ends the script's code after its runs have stopped, in that order, so
  # that the history reads true: every task stopped (and says why), then the
  # vehicles released (the fleet releases an owner's picks when it dies).
  defp stop_code(s, reason) do
    bound = stop_bound(s)
    # Suspended, the code starts nothing more, and a run's `:stopped` answer
    # does not let it go on to its next statement.
    suspend(s.code)
    runs = Dolphin.Engine.Run.runs_of(s.code)
    Enum.each(runs, &send(&1, {:"$dolphin_run_stop", reason}))
    Dolphin.Engine.Run.await(runs, bound)
    Process.unlink(s.code)
    Process.exit(s.code, :kill)
    # A run that was starting as the code was suspended (not registered yet)
    # stops its tree when it gets the code's exit; wait for it too.
    Dolphin.Engine.Run.await(for(%{owner: owner, pid: pid} <- Dolphin.Engine.runs(), owner == s.code, do: pid), bound)
  end

  defp suspend(pid) do
    :erlang.suspend_process(pid)
  rescue
    # It has ended already (its result crossed the stop): nothing to hold back.
    ArgumentError -> false
  end

  # The code's picks are released before the script reports its end (the
  # fleet would release them too when the code dies, but later than that).
  defp release_all(s) do
    Dolphin.Fleet.release_all(s.ctx.fleet, s.code)
  catch
    # No fleet (a script without vehicles in a bare test): nothing was picked.
    :exit, _ -> :ok
  end

  # Real ms to wait for the runs' trees to stop: each platform stop is bounded by stop_timeout_ms.
  defp stop_bound(s), do: s.ctx.clock.real_ms(s.ctx.stop_timeout_ms * 3)

  # `stop_reason`: why a script that did not end on its own was stopped.
  defp finish(s, result, stop_reason \\ nil) do
    release_all(s)

    {name, reason} =
      case result do
        {:ok, :stopped} -> {:stopped, Dolphin.Engine.Failure.format_reason(stop_reason)}
        {:ok, r} -> {r, nil}
        {:error, %Error{kind: kind} = e} -> {if(kind == :halted, do: :halted, else: :failed), Error.format(e)}
      end

    # One moment for the event and the summary: a run's summary line and its
    # last event read the same time.
    ended = s.ctx.clock.now_ms()
    Dolphin.Events.emit(:script_finished, %{script: s.script.file, result: name, reason: reason}, ended)

    result =
      case result do
        {:ok, r} -> {:ok, %{result: r, duration_ms: ended - s.started, started_ms: s.started, file: s.script.file}}
        error -> error
      end

    {caller, tag} = s.reply_to
    send(caller, {tag, self(), result})
    {:stop, :normal, s}
  end

  # What failed, where (the script line), why.
  defp error(script, kind, reason, stack, last_line) do
    line = script_line(script.file, stack) || last_line

    case {kind, reason} do
      {:error, %Dolphin.Script.Halt{message: m}} ->
        %Error{kind: :halted, file: script.file, line: line, message: "halted: #{m}"}

      {:error, %Dolphin.Engine.TaskError{failure: f}} ->
        %Error{kind: :failed, file: script.file, line: line, message: "execute failed: " <> Dolphin.Engine.Failure.message(f), reason: f}

      {:error, %Dolphin.Fleet.AllocationError{} = e} ->
        %Error{kind: :failed, file: script.file, line: line, message: "execute: " <> Exception.message(e), reason: e}

      {:error, %Dolphin.Fleet.PickError{} = e} ->
        %Error{kind: :failed, file: script.file, line: line, message: Exception.message(e), reason: e}

      {:error, e} ->
        %Error{kind: :failed, file: script.file, line: line, message: "#{inspect(e.__struct__)}: #{Exception.message(e)}", reason: e}

      {kind, reason} ->
        %Error{kind: :failed, file: script.file, line: line, message: "#{kind}: #{inspect(reason, charlists: :as_lists)}", reason: reason}
    end
  end

  defp script_line(file, stack) do
    Enum.find_value(stack, fn
      {_m, _f, _a, info} -> if to_string(info[:file] || "") == file, do: info[:line]
      _ -> nil
    end)
  end
end
