defmodule Dolphin.MAVLink.DialectError do
  @moduledoc """
  A dialect definition that could not be read (`Dolphin.MAVLink.XML.load/1`):
  the `file` at fault (nil when the fault spans files), `where` in it (a
  message, a field), and the rule broken — `reason` is `:no_file`,
  `:not_xml`, `:not_mavlink` (the root element is not `<mavlink>`),
  `:unknown_type`, `:no_type`, `:not_an_integer`, `:missing` (an attribute)
  or `:duplicate_id` (two messages with one id); `detail` says more.

      iex> e = %Dolphin.MAVLink.DialectError{file: "x.xml", where: "message PING field seq", reason: :unknown_type, detail: ~s("uint7_t")}
      iex> Exception.message(e)
      ~s(x.xml: message PING field seq: unknown type "uint7_t")
  """

  defexception [:file, :where, :reason, :detail]

  @type reason :: :no_file | :not_xml | :not_mavlink | :unknown_type | :no_type | :not_an_integer | :missing | :duplicate_id
  @type t :: %__MODULE__{file: Path.t() | nil, where: String.t() | nil, reason: reason(), detail: String.t() | nil}

  @impl true
  def message(%__MODULE__{reason: :duplicate_id} = e), do: "#{e.where} defined twice: #{e.detail}"

  def message(%__MODULE__{} = e) do
    text =
      case e.reason do
        :no_file -> "no such dialect file"
        :not_xml -> "not well-formed XML: #{e.detail}"
        :not_mavlink -> "the root element is not <mavlink>"
        :unknown_type -> "unknown type #{e.detail}"
        :no_type -> "no type"
        :not_an_integer -> "not an integer: #{e.detail}"
        :missing -> "missing"
      end

    [e.file, e.where, text] |> Enum.reject(&is_nil/1) |> Enum.join(": ")
  end
end
