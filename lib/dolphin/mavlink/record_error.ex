defmodule Dolphin.MAVLink.RecordError do
  @moduledoc """
  A JSON record (`Dolphin.MAVLink.Record.decode/2`) that does not describe a
  frame. `reason` names the rule broken:

    * `:invalid_json` — `cause` is the `Dolphin.MAVLink.JSONError`;
    * `:not_an_object` — the line is JSON, but not an object;
    * `:no_message` — neither `"msg"` nor `"id"`;
    * `:unknown_message` — no message called `value` in the dialect;
    * `:unknown_id` — no message with id `value`;
    * `:id_mismatch` — the record's `"id"` is `value`, but its `"msg"` has
      another: `detail` is `{name, id}`;
    * `:missing` — no key `key`; `:bad_value` — key `key` has `value`;
    * `:not_a_number` — field `key` of a float type has `value`;
    * `:bad_key` — `signing.secret_key` is not 64 hex digits;
    * `:no_signing` — a signed record without its `"signing"` object.

  A record naming a field its message lacks gives a `Dolphin.MAVLink.FieldError`.

      iex> Exception.message(%Dolphin.MAVLink.RecordError{reason: :missing, key: "fields"})
      ~s(no "fields")
  """

  defexception [:reason, :key, :value, :detail, :cause]

  @type reason ::
          :invalid_json
          | :not_an_object
          | :no_message
          | :unknown_message
          | :unknown_id
          | :id_mismatch
          | :missing
          | :bad_value
          | :not_a_number
          | :bad_key
          | :no_signing

  @type t :: %__MODULE__{
          reason: reason(),
          key: String.t() | nil,
          value: term(),
          detail: term(),
          cause: Exception.t() | nil
        }

  @impl true
  def message(%__MODULE__{} = e) do
    case e.reason do
      :invalid_json -> "not valid JSON: " <> Exception.message(e.cause)
      :not_an_object -> "not a JSON object"
      :no_message -> "no \"msg\" or \"id\""
      :unknown_message -> "unknown message #{inspect(e.value)}"
      :unknown_id -> "unknown message id #{e.value}"
      :id_mismatch -> "\"msg\" #{elem(e.detail, 0)} has id #{elem(e.detail, 1)}, not #{inspect(e.value)}"
      :missing -> "no #{inspect(e.key)}"
      :bad_value -> "bad #{inspect(e.key)}: #{inspect(e.value)}"
      :not_a_number -> "#{e.key}: not a number: #{inspect(e.value)}"
      :bad_key -> "signing.secret_key must be 64 hex digits"
      :no_signing -> "a signed record needs \"signing\" with secret_key, link_id and timestamp"
    end
  end
end
