defmodule Dolphin.Events.Writer do
  @moduledoc """
  Writes every event (see `Dolphin.Events`) to a file, one JSON object per
  line, `t_ms` counted from when the writer started. `stop/1` writes what is
  still queued and closes the file.

      {:ok, w} = Dolphin.Events.Writer.start_link(path: "run.jsonl")
      ...
      :ok = Dolphin.Events.Writer.stop(w)
  """

  use GenServer

  require Logger

  @doc "Starts a writer; options `:path` (required), `:origin_ms` (default: now on `Dolphin.Clock`)."
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts)

  @doc """
  Writes the events received so far, closes the file and stops. It waits
  for the writing as long as it goes on (a large fleet's run may leave
  thousands of events queued at its end): `{:error, :timeout}` only after
  5 minutes, the writer then stopped with what it wrote.
  """
  @spec stop(GenServer.server()) :: :ok | {:error, :timeout}
  def stop(writer) do
    GenServer.stop(writer, :normal, 300_000)
  catch
    :exit, {:timeout, _} ->
      # (Linked to the run: unlinked first, or its kill would take the run with it.)
      Process.unlink(writer)
      Process.exit(writer, :kill)
      {:error, :timeout}

    :exit, _gone ->
      :ok
  end

  # Events written at once, at most: one write per burst, not per event.
  @batch 500

  @impl true
  def init(opts) do
    path = Keyword.fetch!(opts, :path)

    # Raw, with writes gathered for 200 ms: no file server to wait on per
    # event, on a host busy with a thousand vehicles.
    case :file.open(path, [:write, :binary, :raw, {:delayed_write, 65_536, 200}]) do
      {:ok, io} ->
        Dolphin.Events.subscribe()
        # Written on stop, whatever the reason, so no event already received is lost.
        Process.flag(:trap_exit, true)
        {:ok, %{io: io, path: path, failed: false, origin: Keyword.get_lazy(opts, :origin_ms, &Dolphin.Clock.now_ms/0)}}

      {:error, why} ->
        {:stop, "cannot write #{path}: #{:file.format_error(why)}"}
    end
  end

  @impl true
  def handle_info({:dolphin, :events, event}, s), do: {:noreply, write(s, [event | queued(@batch - 1)])}

  def handle_info(_other, s), do: {:noreply, s}

  @impl true
  def terminate(_reason, s) do
    Dolphin.Events.unsubscribe()
    drain(s)
    :file.close(s.io)
  end

  defp drain(s) do
    case queued(@batch) do
      [] -> :ok
      events -> drain(write(s, events))
    end
  end

  # Up to `n` more events already in the mailbox, in order.
  defp queued(0), do: []

  defp queued(n) do
    receive do
      {:dolphin, :events, event} -> [event | queued(n - 1)]
    after
      0 -> []
    end
  end

  # A file that cannot be written (a full disk) is said once and written no
  # more: the run goes on without its record rather than stop mid-flight.
  defp write(%{failed: true} = s, _events), do: s

  defp write(s, events) do
    case :file.write(s.io, Enum.map(events, &[Dolphin.Events.to_json(&1, s.origin), ?\n])) do
      :ok ->
        s

      {:error, why} ->
        Logger.error("--events #{s.path}: cannot write (#{:file.format_error(why)}): the run's events from now on are not in it")
        %{s | failed: true}
    end
  end
end
