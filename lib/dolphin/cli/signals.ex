defmodule Dolphin.CLI.Signals do
  @moduledoc """
  SIGINT (Ctrl-C) and SIGTERM for the mix tasks: from a task's first line
  to its end, a signal never takes the VM's default (the Erlang BREAK menu
  on Ctrl-C, `init:stop/0` on SIGTERM: exit status 0 and an EXIT trace).

  A task first says how a signal ends it while it has nothing to stop in
  order (`exit_on_signal/2`: a line on standard error, then exit status
  130 or 143). Where it has something to stop in order — a script, simulated
  vehicles, a station — it catches them meanwhile (`catch_signals/2`) and
  gets them as messages; `release_signals/0` gives back what was there
  before.

      Dolphin.CLI.Signals.exit_on_signal("dolphin.sim", "stopped before the vehicles started")
      Dolphin.CLI.Signals.catch_signals(self())
      receive do
        {:dolphin_signal, :sigint} -> ...
        {:dolphin_signal, :sigterm} -> ...
      end
      Dolphin.CLI.Signals.release_signals()

  While caught, the first signal is sent; a repeat within `repeat_ms/0` of
  it is taken as the same request (a key pressed twice, `timeout` signalling
  the VM and its process group, `kill` given twice) and ignored, even when
  it comes after the catcher has released them; one that comes later ends
  the VM at once, after the catcher's last words (`:again`).

  All signals go to one relay process. SIGTERM reaches it through the VM's
  signal server (`:os.set_signal/2` and a handler in `:erl_signal_server`
  in place of OTP's, or of the one `mix.exs` installs while `mix` starts a
  task). SIGINT cannot (OTP 25 keeps it for the BREAK handler): a small C
  library (`c_src/dolphin_signals.c`, built into `priv/`) catches it; when
  it was not built, SIGINT keeps its default and `catch_signals/2` says so
  by leaving it out of its answer. Before this module is loaded (while
  `mix` starts the VM and compiles the project) Ctrl-C still opens the
  BREAK menu.
  """

  @behaviour :gen_event

  @typedoc "A signal that stops a task."
  @type signal :: :sigint | :sigterm

  @relay Module.concat(__MODULE__, Relay)

  # A second signal this soon after the first is the same request.
  @repeat_ms 1_000

  @doc """
  From now on, while nothing catches them (`catch_signals/2`), SIGINT and
  SIGTERM end the VM with `status/1`, after the line `mix TASK: SIGNAL:
  what` on standard error. Only when this VM runs `mix task` from the
  command line, outside IEx: a task called by a test or from IEx leaves the
  signals alone. Says whether it took them.
  """
  @spec exit_on_signal(String.t(), String.t()) :: boolean()
  def exit_on_signal(task, what) do
    command? = command?(task)
    if command?, do: change({:base, "mix #{task}", what})
    command?
  end

  @doc """
  Whether this VM runs `mix task` from the command line (`mix dolphin.run
  ...`), outside IEx.
  """
  @spec command?(String.t()) :: boolean()
  def command?(task), do: List.first(System.argv()) == task and not (Code.ensure_loaded?(IEx) and IEx.started?())

  @doc """
  From now on SIGTERM (and SIGINT, when the C library is loaded) sends
  `{:dolphin_signal, signal}` to `pid` instead of its default action (see
  the moduledoc for repeats). Returns the signals caught.

  Option `:again`: a function of the signal run before a later second
  signal ends the VM (last words: what to flush, what to say); by default
  the line `SIGNAL again: exiting at once` on standard error. Called again
  for the same `pid`, it changes the options and keeps what was caught.
  """
  @spec catch_signals(pid(), keyword()) :: [signal()]
  def catch_signals(pid, opts \\ []), do: change({:forward, pid, opts})

  @doc """
  Ends the calling process's `catch_signals/2` (a catcher that ends does
  too): back to what was there before — another catch, `exit_on_signal/2`,
  or with neither, SIGINT and SIGTERM get their default actions back.
  """
  @spec release_signals() :: :ok
  def release_signals do
    if Process.whereis(@relay), do: change({:release, self()})
    :ok
  end

  @doc """
  Waits, for a task that runs something until told to stop (`mix
  dolphin.sim`, `mix dolphin.sensors`): calls `status` every 10 s of real
  time, and `stop` when `left_ms` (a function giving the real ms left, or
  `:infinity`) reaches 0 — or when a caught signal comes, saying so as
  `"SIGNAL: stopping WHAT"`, then exiting with the signal's status.
  """
  @spec run_until((-> number() | :infinity), String.t(), (-> any()), (-> any())) :: :ok
  def run_until(left_ms, what, status, stop) do
    left =
      case left_ms.() do
        :infinity -> 10_000
        ms -> min(10_000, ms)
      end

    if left <= 0 do
      stop.()
      :ok
    else
      receive do
        {:dolphin_signal, sig} ->
          Mix.shell().info("#{name(sig)}: stopping #{what}")
          stop.()
          exit({:shutdown, status(sig)})
      after
        round(left) ->
          status.()
          run_until(left_ms, what, status, stop)
      end
    end
  end

  @doc "How long after a first signal another is taken as its repeat (real milliseconds)."
  @spec repeat_ms() :: pos_integer()
  def repeat_ms, do: @repeat_ms

  @doc """
  The signal in words, for the log and the summary.

      iex> Dolphin.CLI.Signals.name(:sigint)
      "interrupted (SIGINT, Ctrl-C)"
  """
  @spec name(signal()) :: String.t()
  def name(:sigint), do: "interrupted (SIGINT, Ctrl-C)"
  def name(:sigterm), do: "terminated (SIGTERM)"

  @doc """
  The exit status of a task the signal stopped: 128 + the signal's number, as a shell says.

      iex> Dolphin.CLI.Signals.status(:sigterm)
      143
  """
  @spec status(signal()) :: 130 | 143
  def status(:sigint), do: 130
  def status(:sigterm), do: 143

  # The C library replaces these two when it loads; without it SIGINT keeps its default.
  @doc false
  def intercept_sigint(_pid), do: :not_loaded
  @doc false
  def restore_sigint, do: :ok

  @on_load :load_native
  defp load_native do
    with dir when is_list(dir) <- :code.priv_dir(:dolphin),
         {:error, {reason, text}} when reason != :reload <- :erlang.load_nif(:filename.join(dir, ~c"dolphin_signals"), 0) do
      if reason != :load_failed or File.exists?(Path.join(dir, "dolphin_signals.so")),
        do: :error_logger.warning_msg(~c"Ctrl-C will open the BREAK menu: ~ts~n", [text])
    end

    :ok
  end

  # --- the relay: one process per VM, as the signals are the VM's ---

  # A change, made by the relay in the order of the signals it gets: a
  # signal that came before the change is handled as things were. Returns
  # the signals caught.
  defp change(request) do
    relay = Process.whereis(@relay) || start_relay()
    ref = Process.monitor(relay)
    send(relay, {:change, self(), ref, request})

    receive do
      {^ref, caught} ->
        Process.demonitor(ref, [:flush])
        caught

      # It had just ended (released by another caller): a new one takes the change.
      {:DOWN, ^ref, _, _, _} ->
        change(request)
    end
  end

  defp start_relay do
    # Its lines go to the standard error of now: a script being compiled has
    # :standard_error registered to a capture of its warnings for a while.
    err = Process.whereis(:standard_error) || :standard_error
    relay = spawn(fn -> receive(do: ({:installed, caught} -> relay(%{stack: [], caught: caught, err: err, forwarded: nil}))) end)

    try do
      Process.register(relay, @relay)
      send(relay, {:installed, install(relay)})
      relay
    rescue
      # Another caller started one first.
      ArgumentError ->
        Process.exit(relay, :kill)
        Process.whereis(@relay) || start_relay()
    end
  end

  # The stack holds what a signal does, the top's does it: {:forward, pid,
  # opts, monitor, first} (first: when its first signal came, or nil), the
  # newest on top, above at most one {:exit, prefix, what} at the bottom.
  defp relay(state) do
    receive do
      {:dolphin_signal, sig} ->
        relay(on_signal(state, sig, System.monotonic_time(:millisecond)))

      {:change, from, ref, request} ->
        state = apply_change(state, request)
        # Uninstalled before the answer: a relay started after it installs on a clean slate.
        if state.stack == [], do: uninstall()
        send(from, {ref, state.caught})
        if state.stack != [], do: relay(state)

      {:DOWN, mref, :process, _, _} ->
        # A catcher that ended without releasing: what was below it is back.
        state = %{state | stack: Enum.reject(state.stack, &match?({:forward, _, _, ^mref, _}, &1))}
        if state.stack == [], do: uninstall(), else: relay(state)
    end
  end

  defp on_signal(%{stack: [{:forward, pid, opts, mref, nil} | rest]} = state, sig, now) do
    send(pid, {:dolphin_signal, sig})
    %{state | stack: [{:forward, pid, opts, mref, now} | rest], forwarded: now}
  end

  defp on_signal(%{stack: [{:forward, _, _, _, first} | _]} = state, _sig, now) when now - first < @repeat_ms, do: state

  defp on_signal(%{stack: [{:forward, _, opts, _, _} | _]} = state, sig, _now) do
    case opts[:again] do
      nil -> IO.puts(state.err, "#{name(sig)} again: exiting at once")
      again -> last_words(again, sig)
    end

    System.halt(status(sig))
  end

  # The repeat of a request a catcher took and has already finished with
  # (the script stopped before `timeout`'s second signal came) is still that
  # request: the task ends as the first signal said, not with the second.
  defp on_signal(%{stack: [{:exit, _, _} | _], forwarded: at} = state, _sig, now) when is_integer(at) and now - at < @repeat_ms, do: state

  defp on_signal(%{stack: [{:exit, prefix, what} | _]} = state, sig, _now) do
    IO.puts(state.err, "#{prefix}: #{name(sig)}: #{what}")
    System.halt(status(sig))
  end

  defp on_signal(state, _sig, _now), do: state

  # Whatever goes wrong in them, the VM still ends.
  defp last_words(fun, sig) do
    fun.(sig)
  catch
    _, _ -> :ok
  end

  defp apply_change(state, {:base, prefix, what}),
    do: %{state | stack: Enum.filter(state.stack, &match?({:forward, _, _, _, _}, &1)) ++ [{:exit, prefix, what}]}

  defp apply_change(%{stack: [{:forward, pid, _, mref, first} | rest]} = state, {:forward, pid, opts}),
    do: %{state | stack: [{:forward, pid, opts, mref, first} | rest]}

  defp apply_change(state, {:forward, pid, opts}),
    do: %{state | stack: [{:forward, pid, opts, Process.monitor(pid), nil} | state.stack]}

  defp apply_change(state, {:release, pid}) do
    case Enum.split_while(state.stack, &(not match?({:forward, ^pid, _, _, _}, &1))) do
      {above, [{:forward, _, _, mref, _} | below]} ->
        Process.demonitor(mref, [:flush])
        %{state | stack: above ++ below}

      _ ->
        state
    end
  end

  # The handlers that act on SIGTERM when no task catches it: OTP's
  # (init:stop/0), and mix.exs's (exit 143) while mix starts a task or runs
  # the test suite.
  @sigterm_handlers [:erl_signal_handler, Dolphin.MixProject.StartSignals]

  # SIGTERM to `relay` through the signal server, in place of whichever
  # handler was there (OTP's, or mix.exs's while mix started the task) in
  # one step, so that no SIGTERM finds none; SIGINT through the C library.
  defp install(relay) do
    :ok = :os.set_signal(:sigterm, :handle)

    case :gen_event.which_handlers(:erl_signal_server) do
      [] ->
        :ok = :gen_event.add_handler(:erl_signal_server, __MODULE__, relay)

      handlers ->
        cond do
          # One left by a relay that was killed.
          __MODULE__ in handlers ->
            :ok = :gen_event.call(:erl_signal_server, __MODULE__, {:relay, relay})

          # The handler that acts on SIGTERM now (OTP's, or mix.exs's), in
          # one step; handlers of other signals (ExUnit's SIGQUIT) stay.
          default = Enum.find(handlers, &(&1 in @sigterm_handlers)) ->
            :ok = :gen_event.swap_handler(:erl_signal_server, {default, :swap}, {__MODULE__, relay})

          true ->
            :ok = :gen_event.add_handler(:erl_signal_server, __MODULE__, relay)
        end

        # Elixir's own SIGTERM traps would act on it too.
        for {System.SignalHandler, {:sigterm, _}} = trap <- handlers, do: :gen_event.delete_handler(:erl_signal_server, trap, :swap)
    end

    if intercept_sigint(relay) == :ok, do: [:sigint, :sigterm], else: [:sigterm]
  end

  # The handler that was there goes back (`mix test`'s keeps a killed suite
  # from exiting 0; see mix.exs), else OTP's.
  defp uninstall do
    restore_sigint()
    handlers = :gen_event.which_handlers(:erl_signal_server)

    cond do
      __MODULE__ in handlers ->
        {module, args} = :gen_event.call(:erl_signal_server, __MODULE__, :swapped_out)
        :ok = :gen_event.swap_handler(:erl_signal_server, {__MODULE__, :swap}, {module, args})

      Enum.any?(handlers, &(&1 in @sigterm_handlers)) ->
        :ok

      true ->
        :ok = :gen_event.add_handler(:erl_signal_server, :erl_signal_handler, [])
    end

    Process.unregister(@relay)
  end

  # --- the handler in :erl_signal_server ---

  # The state: the relay, and the handler to put back on release: the one
  # swapped out if it said how to restore it (`{module, args}` from its
  # terminate/2), else OTP's.
  @impl :gen_event
  def init({relay, {module, _args} = swapped_out}) when is_atom(module), do: {:ok, {relay, swapped_out}}
  def init({relay, _swapped_out}), do: {:ok, {relay, {:erl_signal_handler, []}}}
  def init(relay), do: {:ok, {relay, {:erl_signal_handler, []}}}

  @impl :gen_event
  def handle_event(:sigterm, {relay, _} = state) do
    send(relay, {:dolphin_signal, :sigterm})
    {:ok, state}
  end

  # The other signals keep OTP's actions (SIGUSR1: a crash dump, SIGQUIT: halt).
  def handle_event(other, state) do
    {:ok, _} = :erl_signal_handler.handle_event(other, [])
    {:ok, state}
  end

  @impl :gen_event
  def handle_call({:relay, relay}, {_old, swapped_out}), do: {:ok, :ok, {relay, swapped_out}}
  def handle_call(:swapped_out, {_relay, swapped_out} = state), do: {:ok, swapped_out, state}
  def handle_call(_request, state), do: {:ok, :ok, state}
end
