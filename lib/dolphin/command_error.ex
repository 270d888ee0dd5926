defmodule Dolphin.CommandError do
  @moduledoc """
  A MAVLink command that did not succeed: which command, on which vehicle, and
  why (`result`: the vehicle's `MAV_RESULT` as an atom — `:denied`,
  `:temporarily_rejected`, `:unsupported`, `:failed`, `:cancelled`, ... — or
  `:timeout` when no answer came within the retries, `:vehicle_gone` when the
  vehicle's process went away, `:not_sent` when the ground station itself
  declined, e.g. a mode the vehicle does not have).

      iex> e = %Dolphin.CommandError{command: :mav_cmd_component_arm_disarm, vehicle: 3, result: :denied, attempts: 1}
      iex> Exception.message(e)
      "vehicle 3 refused MAV_CMD_COMPONENT_ARM_DISARM: MAV_RESULT_DENIED"
  """

  defexception [:command, :vehicle, :result, :attempts, :detail]

  @type t :: %__MODULE__{
          command: atom() | non_neg_integer(),
          vehicle: byte(),
          result: atom(),
          attempts: non_neg_integer(),
          detail: String.t() | nil
        }

  @impl true
  def message(%__MODULE__{command: command, vehicle: vehicle, result: result} = e) do
    name = if is_atom(command), do: command |> Atom.to_string() |> String.upcase(), else: "command #{command}"

    base =
      case result do
        :timeout -> "vehicle #{vehicle} did not answer #{name} (#{e.attempts} attempts)"
        :vehicle_gone -> "vehicle #{vehicle} went away while running #{name}"
        :not_sent -> "#{name} not sent to vehicle #{vehicle}"
        result -> "vehicle #{vehicle} refused #{name}: MAV_RESULT_#{result |> Atom.to_string() |> String.upcase()}"
      end

    if e.detail, do: base <> " (" <> e.detail <> ")", else: base
  end
end
