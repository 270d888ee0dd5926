defmodule Dolphin.MAVLink.FieldError do
  @moduledoc """
  A message field that cannot be set or encoded: `reason` is
  `:unknown_field` (the message `msg` has no field `field`) or `:bad_value`
  (`value` cannot be encoded; `detail` says what the field takes, and which
  element of an array is wrong). `msg` and `field` are nil when the value was
  checked on its own, before it was known whose it is.

      iex> e = %Dolphin.MAVLink.FieldError{msg: "HEARTBEAT", field: "colour", reason: :unknown_field}
      iex> Exception.message(e)
      ~s(HEARTBEAT has no field "colour")
      iex> e = %Dolphin.MAVLink.FieldError{msg: "HEARTBEAT", field: :type, value: 300, reason: :bad_value, detail: "expected an integer in 0..255"}
      iex> Exception.message(e)
      "cannot encode HEARTBEAT.type = 300: expected an integer in 0..255"
  """

  defexception [:msg, :field, :value, :reason, :detail]

  @type t :: %__MODULE__{
          msg: String.t() | nil,
          field: atom() | String.t() | nil,
          value: term(),
          reason: :unknown_field | :bad_value,
          detail: String.t() | nil
        }

  @impl true
  def message(%__MODULE__{reason: :unknown_field} = e), do: "#{e.msg} has no field #{inspect(to_string(e.field))}"
  def message(%__MODULE__{reason: :bad_value, msg: nil} = e), do: "cannot encode #{inspect(e.value)}: #{e.detail}"
  def message(%__MODULE__{reason: :bad_value} = e), do: "cannot encode #{e.msg}.#{e.field} = #{inspect(e.value)}: #{e.detail}"
end
