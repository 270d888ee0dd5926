defmodule Dolphin.CLI.Stdout do
  @moduledoc """
  A command whose standard output is closed under it — piped into a reader
  that has read enough, as in `mix mavlink.decode run.tlog --tlog | head -1`
  — ends at once and quietly, with exit status 141 (128 + SIGPIPE's 13: what
  a shell reports for a command a closed pipe ended). It does not go on with
  work whose output nobody reads, and prints no error about it.

  The VM writes standard output through one process, `:user`, which exits
  when the pipe is closed; whatever the command writes or reads
  afterwards fails, and the exit is logged. `watch/0`, called first by the
  tasks that print, gives the calling process (and those it starts) a group
  leader that passes every I/O request on to `:user` and, when `:user` exits
  that way, ends the VM before any of them gets an error back, with those
  logs left out.
  """

  # 128 + SIGPIPE (13).
  @closed_status 141

  @doc """
  Watches standard output for the calling process and those it starts (see
  above). Does nothing under IEx, whose console is not standard output.
  """
  @spec watch() :: :ok
  def watch do
    user = Process.whereis(:user)

    if user != nil and Process.group_leader() == user do
      quiet_logs(user)
      Process.group_leader(self(), start(user, fn -> System.halt(@closed_status) end))
    end

    :ok
  end

  @doc """
  A group leader that passes I/O requests on to `device` and calls
  `on_closed` when `device` exits because its pipe was closed; with any
  other exit reason it exits too.
  """
  @spec start(pid(), (-> any())) :: pid()
  def start(device, on_closed) do
    caller = self()

    leader =
      spawn(fn ->
        # Ahead of the processes whose output it carries: the end comes before
        # any of them notices that the device is gone.
        Process.flag(:priority, :high)
        ref = Process.monitor(device)
        send(caller, {self(), :watching})
        relay(device, ref, on_closed)
      end)

    # Watching from the start: an end of the device a moment later is seen for what it was.
    receive do
      {^leader, :watching} -> leader
    end
  end

  defp relay(device, ref, on_closed) do
    receive do
      # The reply goes from the device to the caller directly.
      {:io_request, _from, _reply_as, _request} = request ->
        send(device, request)
        relay(device, ref, on_closed)

      {:DOWN, ^ref, :process, _, reason} ->
        if closed?(reason), do: on_closed.(), else: exit(reason)

      _other ->
        relay(device, ref, on_closed)
    end
  end

  # The pipe was closed: the device's port met it (:epipe), or the device
  # wrote to its port once the port had gone for that reason.
  defp closed?(:epipe), do: true
  defp closed?({:badarg, [{:erlang, :port_command, _, _} | _]}), do: true
  defp closed?(_reason), do: false

  # `:user` exiting takes its supervisor along, and both are logged as
  # crashes (and the console log handler, which writes to `:user`, fails):
  # about a closed pipe, which ends the command anyway.
  defp quiet_logs(user) do
    {:links, linked} = Process.info(user, :links)
    pids = [user | Enum.filter(linked, &is_pid/1)]
    _ = :logger.add_primary_filter(:dolphin_stdout_closed, {&__MODULE__.drop_closed/2, pids})
    :ok
  end

  @doc false
  # A :logger filter: drops what the processes of standard output (`pids`)
  # log, and their supervisor's report of their end.
  @spec drop_closed(map(), [pid()]) :: :stop | :ignore
  def drop_closed(%{meta: meta, msg: msg}, pids) do
    if Map.get(meta, :pid) in pids or offender(msg) in pids, do: :stop, else: :ignore
  end

  def drop_closed(_event, _pids), do: :ignore

  defp offender({:report, %{report: report}}) when is_list(report) do
    case report[:offender] do
      offender when is_list(offender) -> offender[:pid]
      _ -> nil
    end
  end

  defp offender(_msg), do: nil
end
