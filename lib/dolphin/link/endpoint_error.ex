defmodule Dolphin.Link.EndpointError do
  @moduledoc """
  An endpoint that could not be read (`Dolphin.Link.Endpoint.parse/1`) or
  opened (`Dolphin.Link.connect/2`). `endpoint` is the string given (or the
  endpoint opened), `reason` the rule broken:

    * reading: `:bad_form` (not `KIND:HOST:PORT`), `:unknown_kind`,
      `:bad_port`, `:no_host`, `:unresolved` (the host name resolves to no
      address); `detail` is what was found;
    * opening: `:already_connected`, `:cannot_open` (`detail`: the
      system's words, such as "address already in use"), `:failed` (`detail`:
      what the link's start returned).

      iex> {:error, e} = Dolphin.Link.Endpoint.parse("udpin:0.0.0.0:70000")
      iex> {e.reason, e.detail}
      {:bad_port, "70000"}
      iex> Exception.message(e)
      ~s|endpoint "udpin:0.0.0.0:70000": bad port "70000" (expected 0..65535)|
  """

  defexception [:endpoint, :reason, :detail]

  @type reason :: :bad_form | :unknown_kind | :bad_port | :no_host | :unresolved | :already_connected | :cannot_open | :failed
  @type t :: %__MODULE__{endpoint: String.t(), reason: reason(), detail: String.t() | nil}

  @impl true
  def message(%__MODULE__{endpoint: endpoint, reason: reason, detail: detail}) do
    case reason do
      :bad_form -> "endpoint #{inspect(endpoint)}: expected KIND:HOST:PORT, e.g. udpin:0.0.0.0:14550"
      :unknown_kind -> "endpoint #{inspect(endpoint)}: unknown kind #{inspect(detail)} (expected udpin, udpout or tcp)"
      :bad_port -> "endpoint #{inspect(endpoint)}: bad port #{inspect(detail)} (expected 0..65535)"
      :no_host -> "endpoint #{inspect(endpoint)}: no host"
      :unresolved -> "endpoint #{inspect(endpoint)}: cannot resolve host #{inspect(detail)}"
      :already_connected -> "#{endpoint}: already connected"
      :cannot_open -> "#{endpoint}: cannot open: #{detail}"
      :failed -> "#{endpoint}: #{detail}"
    end
  end
end
