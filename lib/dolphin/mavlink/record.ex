defmodule Dolphin.MAVLink.Record do
  @moduledoc """
  Frames as JSON records, one object per line, in the conventions of the
  MAVLink test vectors (`scripts/make_vectors.py` makes the project's, and
  describes them in `test/vectors/README.md`):

      {"msg":"HEARTBEAT","id":0,"mavlink":2,"signed":false,"sysid":1,"compid":1,"seq":0,
       "fields":{"type":2,"autopilot":3,...}}

  `fields` are keyed by XML field name in XML order. Integers are exact;
  floats are the shortest decimal that reads back to the same float (`-0.0`
  kept); NaN and infinities are the strings `"NaN"`, `"Infinity"`,
  `"-Infinity"`; `char[N]` fields are strings; arrays are lists of N elements.
  Signed frames carry `"signing": {"link_id", "timestamp"}` (and `"secret_key"`
  in hex when known).

  Reading and writing go through `Dolphin.MAVLink.JSON`, which keeps every bit
  of integers and floats.
  """

  alias Dolphin.MAVLink.{FieldError, Frame, JSON, Message, RecordError}

  @doc "The JSON line (without newline) of a decoded frame. `opts`: `:key` to include as `secret_key`."
  @spec encode(Frame.t(), keyword()) :: iodata()
  def encode(%Frame{message: message} = frame, opts \\ []) when message != nil do
    base = [
      {"msg", Message.name(message)},
      {"id", frame.msgid},
      {"mavlink", frame.version},
      {"signed", frame.signature != nil},
      {"sysid", frame.sysid},
      {"compid", frame.compid},
      {"seq", frame.seq},
      {"fields", {:object, Enum.map(Message.to_fields(message), fn {k, v} -> {Atom.to_string(k), v} end)}}
    ]

    signing =
      case frame.signature do
        nil ->
          []

        sig ->
          key = if opts[:key], do: [{"secret_key", Base.encode16(opts[:key], case: :lower)}], else: []
          [{"signing", {:object, key ++ [{"link_id", sig.link_id}, {"timestamp", sig.timestamp}]}}]
      end

    JSON.encode({:object, base ++ signing})
  end

  @doc """
  Reads one JSON record into the message and `Dolphin.MAVLink.Frame.encode/2`
  options that reproduce its frame. The `frame` and `profile` keys are ignored.
  A line that is no record of a frame gives a `Dolphin.MAVLink.RecordError`,
  one naming a field its message lacks a `Dolphin.MAVLink.FieldError`.
  """
  @spec decode(binary(), module()) :: {:ok, Message.t(), keyword()} | {:error, RecordError.t() | FieldError.t()}
  def decode(line, dialect) do
    with {:ok, map} <- parse(line),
         {:ok, module} <- message_module(map, dialect),
         {:ok, fields} <- fetch(map, "fields", &is_map/1),
         {:ok, message} <- Message.new(module, Enum.map(fields, fn {k, v} -> {k, v} end)),
         {:ok, message} <- convert_floats(message),
         {:ok, opts} <- header(map) do
      {:ok, message, opts}
    end
  end

  defp parse(line) do
    case JSON.decode(line) do
      {:ok, map} when is_map(map) -> {:ok, map}
      {:ok, _other} -> {:error, %RecordError{reason: :not_an_object}}
      {:error, e} -> {:error, %RecordError{reason: :invalid_json, cause: e}}
    end
  end

  defp message_module(map, dialect) do
    case {Map.get(map, "msg"), Map.get(map, "id")} do
      {name, id} when is_binary(name) ->
        case dialect.message_module(name) do
          nil -> {:error, %RecordError{reason: :unknown_message, value: name}}
          module when id == nil -> {:ok, module}
          module -> if module.__mavlink__(:id) == id, do: {:ok, module}, else: {:error, %RecordError{reason: :id_mismatch, value: id, detail: {name, module.__mavlink__(:id)}}}
        end

      {nil, id} when is_integer(id) ->
        case dialect.message_info(id) do
          nil -> {:error, %RecordError{reason: :unknown_id, value: id}}
          {module, _, _, _} -> {:ok, module}
        end

      _ ->
        {:error, %RecordError{reason: :no_message}}
    end
  end

  defp header(map) do
    with {:ok, version} <- fetch(map, "mavlink", &(&1 in [1, 2]), 2),
         {:ok, sysid} <- fetch(map, "sysid", &byte?/1, 0),
         {:ok, compid} <- fetch(map, "compid", &byte?/1, 0),
         {:ok, seq} <- fetch(map, "seq", &byte?/1, 0),
         {:ok, signed} <- fetch(map, "signed", &is_boolean/1, false),
         {:ok, signing} <- signing(signed, Map.get(map, "signing")) do
      {:ok, [version: version, sysid: sysid, compid: compid, seq: seq] ++ signing}
    end
  end

  defp signing(false, _), do: {:ok, []}

  defp signing(true, %{"secret_key" => hex, "link_id" => link_id, "timestamp" => ts})
       when is_binary(hex) and is_integer(link_id) and link_id in 0..255 and is_integer(ts) and ts >= 0 and ts < 0x1000000000000 do
    case Dolphin.MAVLink.Signing.decode_key(hex) do
      {:ok, key} -> {:ok, signing: %{key: key, link_id: link_id, timestamp: ts}}
      :error -> {:error, %RecordError{reason: :bad_key}}
    end
  end

  defp signing(true, _), do: {:error, %RecordError{reason: :no_signing}}

  defp fetch(map, key, valid?, default \\ :required) do
    case Map.fetch(map, key) do
      {:ok, v} -> if valid?.(v), do: {:ok, v}, else: {:error, %RecordError{reason: :bad_value, key: key, value: v}}
      :error when default == :required -> {:error, %RecordError{reason: :missing, key: key}}
      :error -> {:ok, default}
    end
  end

  defp byte?(v), do: is_integer(v) and v in 0..255

  # JSON carries NaN and infinities as strings, and may write a float as an integer.
  defp convert_floats(%module{} = message) do
    Enum.reduce_while(module.__mavlink__(:fields), {:ok, message}, fn
      %{type: t, name: name}, {:ok, msg} when t in [:float, :double] ->
        case from_json_float(Map.fetch!(msg, name)) do
          {:ok, v} -> {:cont, {:ok, Map.put(msg, name, v)}}
          :error -> {:halt, {:error, %RecordError{reason: :not_a_number, key: "#{Message.name(msg)}.#{name}", value: Map.fetch!(msg, name)}}}
        end

      _field, acc ->
        {:cont, acc}
    end)
  end

  defp from_json_float(list) when is_list(list) do
    list
    |> Enum.map(&from_json_float/1)
    |> Enum.reduce_while({:ok, []}, fn
      {:ok, v}, {:ok, acc} -> {:cont, {:ok, [v | acc]}}
      :error, _ -> {:halt, :error}
    end)
    |> case do
      {:ok, acc} -> {:ok, Enum.reverse(acc)}
      :error -> :error
    end
  end

  defp from_json_float(v) when is_float(v), do: {:ok, v}
  defp from_json_float(v) when is_integer(v) do
    {:ok, v * 1.0}
  rescue
    # Beyond the range of a double.
    ArithmeticError -> :error
  end
  defp from_json_float("NaN"), do: {:ok, :nan}
  defp from_json_float("Infinity"), do: {:ok, :infinity}
  defp from_json_float("-Infinity"), do: {:ok, :neg_infinity}
  defp from_json_float(_), do: :error
end
