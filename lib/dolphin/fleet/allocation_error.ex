defmodule Dolphin.Fleet.AllocationError do
  @moduledoc """
  No allocation of vehicles to the platform tasks of a run exists. `task` is
  the platform task that cannot be served (with the others that need the
  vehicles it could use, if any), `message` says why.
  """
  defexception [:task_id, :task_name, :message]

  @type t :: %__MODULE__{task_id: integer() | nil, task_name: String.t() | nil, message: String.t()}
end
