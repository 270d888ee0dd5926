defmodule Dolphin.ParamError do
  @moduledoc """
  A parameter that could not be set or read on a vehicle: which, on which
  vehicle, and why (`result`: `:timeout` when no PARAM_VALUE came within
  the retries, `:refused` when the vehicle answered with another value than
  the one asked — it keeps another: a whole number for an integer type, a value it bounds —,
  `:vehicle_gone` when the vehicle's process went away, `:unknown` when the
  vehicle's parameter list has no such name: `detail` then names the ones
  near).

      iex> e = %Dolphin.ParamError{param: "FENCE_ACTION", vehicle: 3, result: :refused, asked: 9.0, kept: 1.0, attempts: 1}
      iex> Exception.message(e)
      "vehicle 3 kept FENCE_ACTION at 1 when asked for 9"
  """

  defexception [:param, :vehicle, :result, :asked, :kept, :attempts, :detail]

  @type t :: %__MODULE__{param: String.t(), vehicle: term(), result: atom(), asked: float() | nil, kept: float() | nil, attempts: non_neg_integer(), detail: String.t() | nil}

  @impl true
  def message(%__MODULE__{param: param, vehicle: vehicle} = e) do
    base =
      case e.result do
        :timeout -> "vehicle #{vehicle} did not answer for parameter #{param} (#{e.attempts} attempts)"
        :refused -> "vehicle #{vehicle} kept #{param} at #{number(e.kept)} when asked for #{number(e.asked)}"
        :vehicle_gone -> "vehicle #{vehicle} went away while setting #{param}"
        :unknown -> "vehicle #{vehicle} has no parameter #{param}"
        :failed -> "parameter #{param} on vehicle #{vehicle} failed"
        other -> "parameter #{param} on vehicle #{vehicle}: #{other}"
      end

    if e.detail, do: base <> " (" <> e.detail <> ")", else: base
  end

  defp number(v) when is_number(v), do: Dolphin.Vehicles.ParamProtocol.show(v)
  defp number(v), do: inspect(v)
end
