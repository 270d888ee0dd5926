defmodule Dolphin.Console.Supervisor do
  @moduledoc false
  # The console's processes, started with the application so that any IEx
  # session on the node (`iex -S mix dolphin.console`, `iex -S mix
  # dolphin.run`, a remote shell) finds them: the event store, the
  # background runs and the commands run from a session. one_for_one: they do not depend on each other (a
  # restarted event store forgets its history, the runs go on).
  use Supervisor

  def start_link(opts \\ []), do: Supervisor.start_link(__MODULE__, opts, name: __MODULE__)

  @impl true
  def init(_opts) do
    children = [
      %{id: Dolphin.Console.EventLog, start: {Dolphin.Console.EventLog, :start_link, [[]]}},
      %{id: Dolphin.Console.Runs, start: {Dolphin.Console.Runs, :start_link, [[]]}},
      # A command run from the session that started it (`iex -S mix
      # dolphin.run`): in the background, the console usable meanwhile.
      {Task.Supervisor, name: Dolphin.Console.Commands}
    ]

    Supervisor.init(children, strategy: :one_for_one)
  end
end
