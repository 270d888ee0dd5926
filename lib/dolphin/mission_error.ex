defmodule Dolphin.MissionError do
  @moduledoc """
  A mission transfer that did not succeed: the operation (`:upload`,
  `:download`, `:clear`), the vehicle, the mission type, and why — the
  vehicle's `MAV_MISSION_RESULT` as an atom (`:no_space`, `:invalid_sequence`,
  `:unsupported`, `:denied`, `:operation_cancelled`, ...), or `:timeout` when
  the vehicle stopped answering within the retries or the time limit,
  `:unconfirmed` when every item of an upload went out but the vehicle's
  final MISSION_ACK never came (only reading the mission back tells whether
  it holds it), `:vehicle_gone` when the vehicle's process went away.

      iex> e = %Dolphin.MissionError{operation: :upload, vehicle: 2, mission_type: :mission, result: :no_space}
      iex> Exception.message(e)
      "vehicle 2 refused the mission upload: MAV_MISSION_NO_SPACE"
  """

  defexception [:operation, :vehicle, :mission_type, :result, :detail]

  @type t :: %__MODULE__{
          operation: :upload | :download | :clear,
          vehicle: byte(),
          mission_type: :mission | :fence | :rally,
          result: atom(),
          detail: String.t() | nil
        }

  @impl true
  def message(%__MODULE__{} = e) do
    what = if e.mission_type == :mission, do: "mission", else: "#{e.mission_type} list"

    base =
      case e.result do
        :timeout -> "vehicle #{e.vehicle} stopped answering during the #{what} #{e.operation}"
        :vehicle_gone -> "vehicle #{e.vehicle} went away during the #{what} #{e.operation}"
        :unconfirmed -> "vehicle #{e.vehicle} did not confirm the #{what} #{e.operation}"
        result -> "vehicle #{e.vehicle} refused the #{what} #{e.operation}: MAV_MISSION_#{result |> Atom.to_string() |> String.upcase()}"
      end

    if e.detail, do: base <> " (" <> e.detail <> ")", else: base
  end
end
