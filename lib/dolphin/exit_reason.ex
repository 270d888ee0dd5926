defmodule Dolphin.ExitReason do
  @moduledoc """
  How a process ended, in words: an exit reason as text, for any layer that
  reports a process it waited on (a vehicle's protocol exchange, a task, a
  script). The engine words the reasons it knows (`Dolphin.Engine.Failure`)
  by giving its own wording of what a `{:shutdown, reason}` carries.

      iex> Dolphin.ExitReason.words(:killed)
      "was killed"
      iex> Dolphin.ExitReason.words({:shutdown, "the link closed"})
      "was shut down (the link closed)"
      iex> Dolphin.ExitReason.words({:badmatch, 3})
      "crashed ({:badmatch, 3})"
  """

  @doc """
  An exit reason in words; `detail` words what a `{:shutdown, detail}`
  carries (by default: text as it is, anything else as the term).
  """
  @spec words(term(), (term() -> String.t())) :: String.t()
  def words(reason, detail \\ &detail/1)
  def words(:normal, _detail), do: "ended"
  def words(:killed, _detail), do: "was killed"
  def words(:shutdown, _detail), do: "was shut down"
  def words({:shutdown, reason}, detail), do: "was shut down (#{detail.(reason)})"
  def words(:noproc, _detail), do: "was not running"
  def words({%_{__exception__: true} = e, _stack}, _detail), do: "raised #{inspect(e.__struct__)}: #{Exception.message(e)}"
  # A reason no one foresaw: the term itself is the most truthful text.
  def words(other, _detail), do: "crashed (#{inspect(other, charlists: :as_lists)})"

  defp detail(text) when is_binary(text), do: text
  defp detail(%_{__exception__: true} = e), do: Exception.message(e)
  defp detail(other), do: inspect(other, charlists: :as_lists)
end
