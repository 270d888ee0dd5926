defmodule Dolphin.CLI.Teardown do
  @moduledoc """
  What a command undoes when it ends (`mix dolphin.run`'s run, `mix
  dolphin.station`): each thing it starts — a link, simulated vehicles, a
  writer, a signal catch — is deferred here as it starts, tagged with a
  kind, and undone newest first, so that the last started is the first
  stopped (the simulator before its link). The stack is kept in the
  command's own process: a command that raises half way still undoes all
  it started, from its `after`.

      Teardown.begin()
      Teardown.defer(fn -> Dolphin.Link.disconnect(link) end, :vehicles)
      Teardown.defer(fn -> Renderer.stop(renderer) end, :output)
      Teardown.run(:output)   # the outputs first (they show the run, not its teardown)
      Teardown.run_all()      # then the rest, newest first
  """

  @key {__MODULE__, :stack}

  @doc "Starts an empty stack in the calling process (one that was there is dropped)."
  @spec begin() :: :ok
  def begin do
    Process.put(@key, [])
    :ok
  end

  @doc "Defers `fun` (undone by `run/1` of its `kind`, or `run_all/0`)."
  @spec defer((-> any()), atom()) :: :ok
  def defer(fun, kind \\ :other) when is_function(fun, 0) do
    Process.put(@key, [{kind, fun} | Process.get(@key, [])])
    :ok
  end

  @doc "Undoes what was deferred with `kind`, newest first; the rest stays."
  @spec run(atom()) :: :ok
  def run(kind) do
    {these, others} = Enum.split_with(Process.get(@key, []), &match?({^kind, _}, &1))
    Process.put(@key, others)
    Enum.each(these, fn {_, fun} -> fun.() end)
  end

  @doc "Undoes everything deferred, newest first, and ends the stack."
  @spec run_all() :: :ok
  def run_all do
    Enum.each(Process.delete(@key) || [], fn {_, fun} -> fun.() end)
  end
end
