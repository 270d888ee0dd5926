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

  @doc "Starts a writer; options `:path` (required), `:origin_ms` (default: now on `Dolphin.Clock`)."
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts)

  @doc "Writes the events received so far, closes the file and stops."
  @spec stop(GenServer.server()) :: :ok
  def stop(writer), do: GenServer.stop(writer, :normal, 30_000)

  @impl true
  def init(opts) do
    path = Keyword.fetch!(opts, :path)

    case File.open(path, [:write, :binary]) do
      {:ok, io} ->
        Dolphin.Events.subscribe()
        # Written on stop, whatever the reason, so no event already received is lost.
        Process.flag(:trap_exit, true)
        {:ok, %{io: io, origin: Keyword.get_lazy(opts, :origin_ms, &Dolphin.Clock.now_ms/0)}}

      {:error, why} ->
        {:stop, "cannot write #{path}: #{:file.format_error(why)}"}
    end
  end

  @impl true
  def handle_info({:dolphin, :events, event}, s) do
    IO.binwrite(s.io, [Dolphin.Events.to_json(event, s.origin), ?\n])
    {:noreply, s}
  end

  def handle_info(_other, s), do: {:noreply, s}

  @impl true
  def terminate(_reason, s) do
    Dolphin.Events.unsubscribe()
    drain(s)
    File.close(s.io)
  end

  defp drain(s) do
    receive do
      {:dolphin, :events, event} ->
        IO.binwrite(s.io, [Dolphin.Events.to_json(event, s.origin), ?\n])
        drain(s)
    after
      0 -> :ok
    end
  end
end
