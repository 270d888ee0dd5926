defmodule Dolphin.Engine.Context do
  @moduledoc """
  What a script and its runs share: the fleet (and its vehicle source), the
  time source, the owner of picks (the script's process), the signal table,
  and settings. It sits in the process dictionary of the script's process and
  of every engine process working for it (node processes, action code), so
  that the script vocabulary (`pick`, `battery`, `post`, ...) needs no
  explicit argument. Outside a script, `current/0` is the default context:
  the fleet of the calling process's `Dolphin.Instance`, `Dolphin.Clock`,
  the calling process as owner.

  Fields: `instance` (the `Dolphin.Instance` whose vehicles, views, events
  and clock the runs use: every process the context is put in works in
  it), `fleet` (a `Dolphin.Fleet` name or pid), `source`, `clock` (a
  `Dolphin.Engine.TimeSource`), `owner` (pid), `signals` (a
  `Dolphin.Engine.Signals` table), `tick_ms` (the slow re-evaluation tick of
  conditions, default 1000), `stop_timeout_ms` (bound on a platform task's
  stop, default 15_000), `script` (the script runner, or nil), `output` (a
  function given each `message` line, or nil), `ask` (a function from prompt
  to answer, or nil: standard input), `platform_opts` (options every
  platform task of the context is started with, beside the engine's own:
  how the run flies the tasks of a platform — the pre-flight check's dry
  run and a run on fake vehicles give the mission platform `:missions`,
  see `Dolphin.Mission.Platform`).
  """

  defstruct instance: nil,
            fleet: nil,
            source: nil,
            clock: Dolphin.Engine.TimeSource.Clock,
            owner: nil,
            signals: Dolphin.Engine.Signals,
            tick_ms: 1_000,
            stop_timeout_ms: 15_000,
            script: nil,
            output: nil,
            ask: nil,
            platform_opts: []

  @type t :: %__MODULE__{}

  @key :"$dolphin_context"

  @doc "The context of the calling process (or the default one); `owner` filled in."
  @spec current() :: t()
  def current do
    case Process.get(@key) do
      nil -> complete(%__MODULE__{owner: self()})
      %__MODULE__{owner: nil} = ctx -> %{ctx | owner: self()}
      ctx -> ctx
    end
  end

  @doc "Makes `ctx` the calling process's context, and its instance the process's (`Dolphin.Instance.put/1`)."
  @spec put(t()) :: t() | nil
  def put(%__MODULE__{} = ctx) do
    ctx = complete(ctx)
    Dolphin.Instance.put(ctx.instance)
    Process.put(@key, ctx)
  end

  # The instance (the caller's) and its fleet, when not given.
  defp complete(%__MODULE__{instance: nil} = ctx), do: complete(%{ctx | instance: Dolphin.Instance.current()})
  defp complete(%__MODULE__{fleet: nil, instance: instance} = ctx), do: %{ctx | fleet: Dolphin.Instance.names(instance).fleet}
  defp complete(ctx), do: ctx

  @doc "A context from options (`:fleet`, `:clock`, `:owner`, ...) over the current one."
  @spec new(keyword()) :: t()
  def new(opts) do
    base = current()
    # Another instance than the current context's brings its own fleet.
    base = if Keyword.has_key?(opts, :instance), do: %{base | fleet: nil, source: nil}, else: base
    ctx = complete(struct!(base, Keyword.take(opts, Map.keys(Map.from_struct(%__MODULE__{})))))
    %{ctx | source: ctx.source || Dolphin.Fleet.source(ctx.fleet)}
  end

  @doc "The vehicle source of a context."
  @spec source(t()) :: Dolphin.Fleet.Source.t()
  def source(%__MODULE__{source: nil, fleet: fleet}), do: Dolphin.Fleet.source(fleet)
  def source(%__MODULE__{source: source}), do: source
end
