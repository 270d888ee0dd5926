defmodule Dolphin.MAVLink.Message do
  @moduledoc """
  What every generated message module provides, and functions over any message.

  A dialect (`Dolphin.MAVLink.Dialect`) generates one struct module per
  message, e.g. `Dolphin.MAVLink.Ardupilotmega.Heartbeat`, whose fields are
  named as in the XML and hold values as described in `Dolphin.MAVLink.Value`.
  Build messages as structs; unset fields are zero (empty string, zero list),
  except HEARTBEAT's `mavlink_version`, which is 3 (MAVLink 2) as senders write it.

      iex> alias Dolphin.MAVLink.Ardupilotmega.Heartbeat
      iex> msg = %Heartbeat{type: 6, autopilot: 8}
      iex> Dolphin.MAVLink.Message.name(msg)
      "HEARTBEAT"
      iex> Dolphin.MAVLink.Message.to_fields(msg)
      [type: 6, autopilot: 8, base_mode: 0, custom_mode: 0, system_status: 0, mavlink_version: 3]
  """

  alias Dolphin.MAVLink.{FieldError, Value}

  @typedoc "A message struct of some dialect."
  @type t :: struct()

  @doc "Static facts of the message: `:id`, `:name`, `:crc_extra`, `:min_len`, `:max_len`, `:dialect`, `:fields`, `:wire`."
  @callback __mavlink__(atom()) :: term()

  @doc "Decodes a payload of exactly `max_len` bytes."
  @callback decode(binary()) :: t()

  @doc "Encodes to the full (`max_len`) wire payload; raises `ArgumentError` on a bad field value."
  @callback encode(t()) :: binary()

  @doc "The message id."
  @spec id(t()) :: non_neg_integer()
  def id(%mod{}), do: mod.__mavlink__(:id)

  @doc "The message name as in the XML."
  @spec name(t()) :: String.t()
  def name(%mod{}), do: mod.__mavlink__(:name)

  @doc "Field values in XML declaration order."
  @spec to_fields(t()) :: keyword()
  def to_fields(%mod{} = message) do
    for %{name: name} <- mod.__mavlink__(:fields), do: {name, Map.fetch!(message, name)}
  end

  @doc """
  Builds a message of `module` from field values given by name (atom or
  string keys); fields not given keep the struct's default (zero, except
  HEARTBEAT's `mavlink_version`, 3). Returns `{:error, %Dolphin.MAVLink.FieldError{}}`
  for an unknown field name; values are checked when the message is encoded.
  """
  @spec new(module(), Enumerable.t()) :: {:ok, t()} | {:error, FieldError.t()}
  def new(module, values) do
    known = Map.new(module.__mavlink__(:fields), &{Atom.to_string(&1.name), &1.name})

    Enum.reduce_while(values, {:ok, struct(module)}, fn {key, value}, {:ok, msg} ->
      case Map.fetch(known, to_string(key)) do
        {:ok, name} -> {:cont, {:ok, Map.put(msg, name, value)}}
        :error -> {:halt, {:error, %FieldError{msg: module.__mavlink__(:name), field: to_string(key), reason: :unknown_field}}}
      end
    end)
  end

  @doc false
  # The general encoder: field by field, raising an ArgumentError that names the
  # message, the field and the value when one cannot be encoded.
  @spec encode_fields!(t()) :: binary()
  def encode_fields!(%module{} = message) do
    module.__mavlink__(:wire)
    |> Enum.map(fn {name, _type, _n} -> encode_field!(module, name, Map.fetch!(message, name)) end)
    |> IO.iodata_to_binary()
  end

  @doc false
  @spec encode_field!(module(), atom(), term()) :: binary()
  def encode_field!(module, name, value) do
    {^name, type, n} = List.keyfind(module.__mavlink__(:wire), name, 0)

    case Value.encode(type, n, value) do
      {:ok, bytes} ->
        bytes

      {:error, error} ->
        raise ArgumentError, Exception.message(%{error | msg: module.__mavlink__(:name), field: name})
    end
  end
end
