defmodule Dolphin.Engine.Action do
  @moduledoc """
  `action do ... end`: runs code once, in its own process (so that it can be
  stopped while it blocks); completes when the code returns, fails if it
  raises, throws or exits.
  """
  use Dolphin.Engine.Task.Struct, fun: nil
  @behaviour Dolphin.Engine.Node

  @type t :: %__MODULE__{fun: (() -> term())}

  @impl true
  def kind, do: :action
  @impl true
  def init(%{fun: fun}), do: {[{:run_code, :action, fun}], nil}
  @impl true
  def handle({:code_result, :action, {:ok, _}}, s), do: {[{:finish, :done}], s}
  def handle({:code_result, :action, {:error, reason}}, s), do: {[{:finish, {:failed, reason}}], s}
end
