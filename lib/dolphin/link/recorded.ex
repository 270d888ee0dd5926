defmodule Dolphin.Link.Recorded do
  @moduledoc """
  The frames each telemetry log recorded lately, so that links writing to
  the same `.tlog` (one vehicle heard on several links) record a frame
  heard on several of them once: a copy is the same vehicle, component,
  sequence number and bytes recorded by *another* link of that file within
  a window. One public ETS table, written by the links themselves, owned
  by this small process, started before the links' supervisor.
  """

  use GenServer

  @table __MODULE__

  @doc false
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(_opts \\ []), do: GenServer.start_link(__MODULE__, :ok, name: __MODULE__)

  @doc """
  Whether link `name` is to record a frame in the log at `path`: true
  unless another link recorded the same frame there within `window_ms` of
  `now_ms` (monotonic ms); a frame to record is remembered as recorded.
  """
  @spec first?(Path.t(), {byte(), byte(), byte()}, binary(), term(), integer(), pos_integer()) :: boolean()
  def first?(path, {sysid, compid, seq}, raw, name, now_ms, window_ms) do
    key = {path, sysid, compid, seq}
    hash = :erlang.phash2(raw)

    case :ets.lookup(@table, key) do
      [{^key, ^hash, other, at}] when other != name and now_ms - at <= window_ms ->
        false

      _ ->
        :ets.insert(@table, {key, hash, name, now_ms})
        true
    end
  end

  @doc """
  Forgets what link `name` recorded at `path` (it stops): that is no copy
  for a link that records to the file next (a new run, which may send the
  very same frames: a deterministic simulation).
  """
  @spec forget(Path.t(), term()) :: :ok
  def forget(path, name) do
    :ets.match_delete(@table, {{path, :_, :_, :_}, :_, name, :_})
    :ok
  end

  @impl true
  def init(:ok) do
    :ets.new(@table, [:named_table, :public, :set, write_concurrency: true, read_concurrency: true])
    {:ok, nil}
  end
end
