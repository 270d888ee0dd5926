defmodule Dolphin.Script.Runner do
  @moduledoc false
  # One process per running script, linked to its caller: it makes the
  # script's signal table and context, runs the script's code in a linked
  # process (the owner of its picks), and ends it — on completion, on `halt`
  # from any of its tasks, at the `--for` deadline, on `Dolphin.Script.stop/2`
  # or when the caller dies. Ending a script that still runs kills its code;
  # its runs, linked to it, stop their task trees (vehicles hold), and the
  # runner waits for them before it reports.

  alias Dolphin.Engine.{Context, Signals}
  alias Dolphin.Script.Error

  def start_link(script, ctx, opts, caller) do
    pid = :proc_lib.spawn_link(__MODULE__, :init, [script, ctx, opts, caller])
    {:ok, pid}
  end

  def init(script, base, opts, caller) do
    Process.flag(:trap_exit, true)
    signals = Signals.new()
    ctx = %{base | signals: signals, script: self(), owner: nil}
    me = self()
    started = ctx.clock.now_ms()

    code =
      :proc_lib.spawn_link(fn ->
        Context.put(%{ctx | owner: self()})
        send(me, {:script_done, self(), execute(script)})
      end)

    Dolphin.Telemetry.emit(:script_started, %{script: script.file}, started)
    if ms = opts[:for], do: ctx.clock.send_after(self(), :deadline, ms)
    loop(%{script: script, caller: caller, code: code, ctx: ctx, started: started})
  end

  defp execute(script) do
    script.module.__script__()
    :ok
  rescue
    e -> {:error, :error, e, __STACKTRACE__, Process.get(:"$dolphin_line")}
  catch
    kind, reason -> {:error, kind, reason, __STACKTRACE__, Process.get(:"$dolphin_line")}
  end

  defp loop(%{code: code, caller: caller} = s) do
    receive do
      {:script_done, ^code, :ok} ->
        finish(s, {:ok, :done})

      {:script_done, ^code, {:error, kind, reason, stack, line}} ->
        finish(s, {:error, error(s.script, kind, reason, stack, line)})

      :deadline ->
        stop_code(s)
        finish(s, {:ok, :stopped})

      {:"$dolphin_script_stop", _reason} ->
        stop_code(s)
        finish(s, {:ok, :stopped})

      {:"$dolphin_halt", text} ->
        stop_code(s)
        finish(s, {:error, %Error{kind: :halted, file: s.script.file, message: "halted: #{text}"}})

      {:EXIT, ^code, reason} ->
        # Died without reporting (killed from outside).
        finish(s, {:error, %Error{kind: :failed, file: s.script.file, message: "the script's process exited: #{inspect(reason)}", reason: reason}})

      {:EXIT, ^caller, _reason} ->
        stop_code(s)
        exit(:normal)

      _other ->
        loop(s)
    end
  end

  defp stop_code(s) do
    Process.unlink(s.code)
    Process.exit(s.code, :kill)
    # Its runs stop their trees as they get the exit; wait until they are done.
    runs = for %{owner: owner, pid: pid} <- Dolphin.Engine.runs(), owner == s.code, do: pid
    Dolphin.Engine.Run.await(runs, s.ctx.clock.real_ms(s.ctx.stop_timeout_ms * 3))
  end

  defp finish(s, result) do
    {name, reason} =
      case result do
        {:ok, r} -> {r, nil}
        {:error, %Error{kind: kind} = e} -> {if(kind == :halted, do: :halted, else: :failed), Error.format(e)}
      end

    Dolphin.Telemetry.emit(:script_finished, %{script: s.script.file, result: name, reason: reason}, s.ctx.clock.now_ms())

    result =
      case result do
        {:ok, r} -> {:ok, %{result: r, duration_ms: s.ctx.clock.now_ms() - s.started, file: s.script.file}}
        error -> error
      end

    send(s.caller, {Dolphin.Script, self(), result})
    exit(:normal)
  end

  # What failed, where (the script line), why.
  defp error(script, kind, reason, stack, last_line) do
    line = script_line(script.file, stack) || last_line

    case {kind, reason} do
      {:error, %Dolphin.Script.Halt{message: m}} ->
        %Error{kind: :halted, file: script.file, line: line, message: "halted: #{m}"}

      {:error, %Dolphin.Engine.TaskError{failure: f}} ->
        %Error{kind: :failed, file: script.file, line: line, message: "execute failed: " <> Dolphin.Engine.Failure.message(f), reason: f}

      {:error, %Dolphin.Engine.AllocationError{} = e} ->
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
