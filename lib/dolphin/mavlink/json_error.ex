defmodule Dolphin.MAVLink.JSONError do
  @moduledoc """
  JSON text that `Dolphin.MAVLink.JSON.decode/1` could not read: the rule
  broken (`reason`), the byte `position` where, and the bytes `found` there
  (at most 12; nil at the end of the input).

      iex> {:error, e} = Dolphin.MAVLink.JSON.decode("[1, 2")
      iex> {e.reason, e.position}
      {:array_separator, 5}
      iex> Exception.message(e)
      "expected , or ] in an array at byte 5, found end of input"
  """

  defexception [:reason, :position, :found]

  @type reason ::
          :trailing_data
          | :expected_value
          | :object_separator
          | :object_colon
          | :object_key
          | :array_separator
          | :string_character
          | :lone_surrogate
          | :bad_escape
          | :number_range
          | :bad_number

  @type t :: %__MODULE__{reason: reason(), position: non_neg_integer(), found: binary() | nil}

  @impl true
  def message(%__MODULE__{reason: reason, position: at, found: found}) do
    found = if found == nil, do: "end of input", else: inspect(found)
    "#{what(reason)} at byte #{at}, found #{found}"
  end

  defp what(:trailing_data), do: "unexpected data after the value"
  defp what(:expected_value), do: "expected a value"
  defp what(:object_separator), do: "expected , or } in an object"
  defp what(:object_colon), do: "expected : after an object key"
  defp what(:object_key), do: "expected a string key"
  defp what(:array_separator), do: "expected , or ] in an array"
  defp what(:string_character), do: "bad character in a string"
  defp what(:lone_surrogate), do: "lone surrogate in a string"
  defp what(:bad_escape), do: "bad \\u escape"
  defp what(:number_range), do: "number out of range"
  defp what(:bad_number), do: "bad number"
end
