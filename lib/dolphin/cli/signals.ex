defmodule Dolphin.CLI.Signals do
  @moduledoc """
  SIGINT (Ctrl-C) and SIGTERM as messages, so that `mix dolphin.run` stops
  its script the way `--for` does — tasks stopped, vehicles told to hold, a
  summary, a `script_finished` event — instead of the VM's default: the
  Erlang BREAK menu on Ctrl-C, `init:stop/0` (an abrupt shutdown) on SIGTERM.

      signals = Dolphin.CLI.Signals.catch_signals(self())
      receive do
        {:dolphin_signal, :sigint} -> ...
        {:dolphin_signal, :sigterm} -> ...
      end
      Dolphin.CLI.Signals.release_signals()

  SIGTERM goes through the VM's signal server (`:os.set_signal/2` and a
  handler in `:erl_signal_server` in place of OTP's). SIGINT cannot (OTP 25
  keeps it for the BREAK handler): a small C library (`c_src/dolphin_signals.c`,
  built into `priv/`) catches it; when it was not built, SIGINT keeps its
  default and `catch_signals/1` says so by leaving it out of its answer.
  """

  @behaviour :gen_event

  @typedoc "A signal that stops a run."
  @type signal :: :sigint | :sigterm

  @doc """
  From now on SIGTERM (and SIGINT, when the C library is loaded) sends
  `{:dolphin_signal, signal}` to `pid` instead of its default action.
  Returns the signals caught.
  """
  @spec catch_signals(pid()) :: [signal()]
  def catch_signals(pid) do
    :ok = :os.set_signal(:sigterm, :handle)
    # OTP's own handler (init:stop on SIGTERM) makes way for ours; it comes back in release_signals/0.
    _ = :gen_event.delete_handler(:erl_signal_server, :erl_signal_handler, :ok)
    _ = :gen_event.delete_handler(:erl_signal_server, __MODULE__, :ok)
    :ok = :gen_event.add_handler(:erl_signal_server, __MODULE__, pid)
    if intercept_sigint(pid) == :ok, do: [:sigint, :sigterm], else: [:sigterm]
  end

  @doc "Gives SIGINT and SIGTERM back their default actions."
  @spec release_signals() :: :ok
  def release_signals do
    restore_sigint()
    _ = :gen_event.delete_handler(:erl_signal_server, __MODULE__, :ok)

    unless :erl_signal_handler in :gen_event.which_handlers(:erl_signal_server),
      do: :ok = :gen_event.add_handler(:erl_signal_server, :erl_signal_handler, [])

    :ok
  end

  @doc """
  The signal in words, for the log and the summary.

      iex> Dolphin.CLI.Signals.name(:sigint)
      "interrupted (SIGINT, Ctrl-C)"
  """
  @spec name(signal()) :: String.t()
  def name(:sigint), do: "interrupted (SIGINT, Ctrl-C)"
  def name(:sigterm), do: "terminated (SIGTERM)"

  @doc """
  The exit status of a run the signal stopped: 128 + the signal's number, as a shell says.

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

  # --- the handler in :erl_signal_server ---

  @impl :gen_event
  def init(pid), do: {:ok, pid}

  @impl :gen_event
  def handle_event(:sigterm, pid) do
    send(pid, {:dolphin_signal, :sigterm})
    {:ok, pid}
  end

  # The other signals keep OTP's actions (SIGUSR1: a crash dump, SIGQUIT: halt).
  def handle_event(other, pid) do
    {:ok, _} = :erl_signal_handler.handle_event(other, [])
    {:ok, pid}
  end

  @impl :gen_event
  def handle_call(_request, pid), do: {:ok, :ok, pid}
end
