defmodule Dolphin.MAVLink.XML do
  @moduledoc """
  Reads MAVLink message-definition XML into plain data.

  `load/1` takes the path of a dialect file (for example `ardupilotmega.xml`),
  follows its `<include>` elements transitively (each file once, paths relative
  to the including file) and returns one `t:definitions/0` map: every message
  sorted by id, every enum with the entries of all files merged (dialects extend
  `MAV_CMD` and friends; included files' entries first), and the list of files
  read, the dialect's own first (the generator declares them
  as `@external_resource` so that editing one recompiles the dialect).

  Nothing here generates code: see `Dolphin.MAVLink.Generator`.

      iex> defs = Dolphin.MAVLink.XML.load!(Path.join(:code.priv_dir(:dolphin), "mavlink/minimal.xml"))
      iex> [heartbeat] = defs.messages
      iex> {heartbeat.id, heartbeat.name, length(heartbeat.fields)}
      {0, "HEARTBEAT", 6}
  """

  require Record

  alias Dolphin.MAVLink.DialectError

  Record.defrecordp(:element, :xmlElement, Record.extract(:xmlElement, from_lib: "xmerl/include/xmerl.hrl"))
  Record.defrecordp(:attribute, :xmlAttribute, Record.extract(:xmlAttribute, from_lib: "xmerl/include/xmerl.hrl"))
  Record.defrecordp(:text, :xmlText, Record.extract(:xmlText, from_lib: "xmerl/include/xmerl.hrl"))

  @typedoc "A field's base type; arrays and `char[N]` strings carry their length separately."
  @type base_type ::
          :uint8 | :int8 | :uint16 | :int16 | :uint32 | :int32 | :uint64 | :int64 | :float | :double | :char

  @type field :: %{
          name: String.t(),
          type: base_type(),
          array_length: pos_integer() | nil,
          enum: String.t() | nil,
          units: String.t() | nil,
          extension: boolean(),
          mavlink_version: boolean(),
          description: String.t()
        }

  @type message :: %{
          id: non_neg_integer(),
          name: String.t(),
          description: String.t(),
          fields: [field()],
          file: Path.t()
        }

  @type entry :: %{name: String.t(), value: integer(), description: String.t()}
  @type enum :: %{name: String.t(), bitmask: boolean(), description: String.t(), entries: [entry()]}

  @type definitions :: %{messages: [message()], enums: [enum()], files: [Path.t()]}

  @doc "Like `load/1` but raises `ArgumentError` with the error's message."
  @spec load!(Path.t()) :: definitions()
  def load!(path) do
    case load(path) do
      {:ok, defs} -> defs
      {:error, error} -> raise ArgumentError, Exception.message(error)
    end
  end

  @doc """
  Loads a dialect and everything it includes.

  Returns `{:error, %Dolphin.MAVLink.DialectError{}}` naming the file and the
  problem when a file is missing, is not XML, or breaks a rule the wire format
  depends on (two messages with one id, an unknown field type).
  """
  @spec load(Path.t()) :: {:ok, definitions()} | {:error, DialectError.t()}
  def load(path) do
    with {:ok, files} <- read_tree(Path.expand(path), []),
         {:ok, messages} <- merge_messages(files) do
      {:ok,
       %{
         messages: messages,
         enums: merge_enums(files),
         files: files |> Enum.reverse() |> Enum.map(& &1.path)
       }}
    end
  end

  # Depth-first over includes. A file joins `acc` before its includes are read,
  # so each is visited once (common.xml is reached from several dialects) and an
  # include cycle ends.
  defp read_tree(path, acc) do
    if Enum.any?(acc, &(&1.path == path)) do
      {:ok, acc}
    else
      with {:ok, doc} <- parse_file(path),
           {:ok, file} <- read_file(path, doc) do
        file.includes
        |> Enum.map(&Path.expand(&1, Path.dirname(path)))
        |> Enum.reduce_while({:ok, [file | acc]}, fn include, {:ok, acc} ->
          case read_tree(include, acc) do
            {:ok, acc} -> {:cont, {:ok, acc}}
            error -> {:halt, error}
          end
        end)
      end
    end
  end

  defp parse_file(path) do
    if File.regular?(path) do
      try do
        {doc, _rest} = :xmerl_scan.file(String.to_charlist(path), quiet: true)
        {:ok, doc}
      catch
        :exit, reason -> {:error, %DialectError{file: path, reason: :not_xml, detail: inspect(reason)}}
      end
    else
      {:error, %DialectError{file: path, reason: :no_file}}
    end
  end

  defp read_file(path, element(name: :mavlink) = root) do
    includes = for el <- children(root, :include), do: content(el)
    messages = for group <- children(root, :messages), msg <- children(group, :message), do: msg
    enums = for group <- children(root, :enums), enum <- children(group, :enum), do: enum

    with {:ok, messages} <- map_ok(messages, &read_message(&1, path)) do
      {:ok, %{path: path, includes: includes, messages: messages, enums: Enum.map(enums, &read_enum/1)}}
    end
  end

  defp read_file(path, _other), do: {:error, %DialectError{file: path, reason: :not_mavlink}}

  defp read_message(el, path) do
    name = attr(el, :name)

    with {:ok, id} <- parse_int(attr(el, :id), path, "message #{name} id"),
         {:ok, fields} <- map_ok(tag_extensions(element_children(el)), &read_field(&1, path, "message #{name}")) do
      {:ok, %{id: id, name: name, description: description(el), fields: fields, file: path}}
    end
  end

  # Fields after the <extensions/> marker are MAVLink 2 extensions.
  defp tag_extensions(children) do
    {tagged, _} =
      Enum.flat_map_reduce(children, false, fn
        element(name: :extensions), _ext -> {[], true}
        element(name: :field) = f, ext -> {[{f, ext}], ext}
        _other, ext -> {[], ext}
      end)

    tagged
  end

  defp read_field({el, extension?}, path, where) do
    name = attr(el, :name)

    with {:ok, type, array_length, version?} <- parse_type(attr(el, :type), path, "#{where} field #{name}") do
      {:ok,
       %{
         name: name,
         type: type,
         array_length: array_length,
         enum: attr(el, :enum),
         units: attr(el, :units),
         extension: extension?,
         mavlink_version: version?,
         description: content(el)
       }}
    end
  end

  @base_types %{
    "uint8_t" => :uint8,
    "int8_t" => :int8,
    "uint16_t" => :uint16,
    "int16_t" => :int16,
    "uint32_t" => :uint32,
    "int32_t" => :int32,
    "uint64_t" => :uint64,
    "int64_t" => :int64,
    "float" => :float,
    "double" => :double,
    "char" => :char
  }

  defp parse_type("uint8_t_mavlink_version", _path, _where), do: {:ok, :uint8, nil, true}

  defp parse_type(type, path, where) when is_binary(type) do
    {base, array_length} =
      case Regex.run(~r/^([a-z0-9_]+)\[(\d+)\]$/, type) do
        [_, base, n] -> {base, String.to_integer(n)}
        nil -> {type, nil}
      end

    case Map.fetch(@base_types, base) do
      {:ok, t} when array_length == nil or array_length > 0 -> {:ok, t, array_length, false}
      _ -> {:error, %DialectError{file: path, where: where, reason: :unknown_type, detail: inspect(type)}}
    end
  end

  defp parse_type(nil, path, where), do: {:error, %DialectError{file: path, where: where, reason: :no_type}}

  defp read_enum(el) do
    {entries, _next} =
      el
      |> children(:entry)
      |> Enum.map_reduce(0, fn entry, next ->
        # An entry without a value takes the next one, as mavgen does.
        value =
          case parse_int(attr(entry, :value), nil, nil) do
            {:ok, v} -> v
            {:error, _} -> next
          end

        {%{name: attr(entry, :name), value: value, description: description(entry)}, value + 1}
      end)

    %{
      name: attr(el, :name),
      bitmask: attr(el, :bitmask) == "true",
      description: description(el),
      entries: entries
    }
  end

  defp merge_messages(files) do
    files
    |> Enum.flat_map(& &1.messages)
    |> Enum.group_by(& &1.id)
    |> Enum.reduce_while({:ok, []}, fn
      {_id, [msg]}, {:ok, acc} ->
        {:cont, {:ok, [msg | acc]}}

      {id, [a, b | _]}, _acc ->
        {:halt, {:error, %DialectError{where: "message id #{id}", reason: :duplicate_id, detail: "#{a.name} in #{a.file} and #{b.name} in #{b.file}"}}}
    end)
    |> case do
      {:ok, msgs} -> {:ok, Enum.sort_by(msgs, & &1.id)}
      error -> error
    end
  end

  # The same enum may be declared in several files, each adding entries.
  # `files` comes from read_tree newest first, so an included file comes before
  # the file including it: base entries first, a dialect's additions after.
  defp merge_enums(files) do
    {order, by_name} =
      files
      |> Enum.flat_map(& &1.enums)
      |> Enum.reduce({[], %{}}, fn enum, {order, by_name} ->
        case Map.fetch(by_name, enum.name) do
          {:ok, prev} ->
            known = MapSet.new(prev.entries, & &1.name)
            added = Enum.reject(enum.entries, &MapSet.member?(known, &1.name))
            merged = %{prev | entries: prev.entries ++ added, bitmask: prev.bitmask or enum.bitmask}
            {order, Map.put(by_name, enum.name, merged)}

          :error ->
            {[enum.name | order], Map.put(by_name, enum.name, enum)}
        end
      end)

    order |> Enum.reverse() |> Enum.map(&Map.fetch!(by_name, &1))
  end

  defp parse_int(nil, path, where), do: {:error, %DialectError{file: path, where: where, reason: :missing}}

  defp parse_int(string, path, where) do
    string = String.trim(string)

    result =
      case string do
        "0x" <> hex -> Integer.parse(hex, 16)
        "0X" <> hex -> Integer.parse(hex, 16)
        dec -> Integer.parse(dec)
      end

    case result do
      {int, ""} -> {:ok, int}
      _ -> {:error, %DialectError{file: path, where: where, reason: :not_an_integer, detail: inspect(string)}}
    end
  end

  defp map_ok(list, fun) do
    list
    |> Enum.reduce_while({:ok, []}, fn item, {:ok, acc} ->
      case fun.(item) do
        {:ok, v} -> {:cont, {:ok, [v | acc]}}
        error -> {:halt, error}
      end
    end)
    |> case do
      {:ok, acc} -> {:ok, Enum.reverse(acc)}
      error -> error
    end
  end

  defp element_children(element(content: content)), do: Enum.filter(content, &Record.is_record(&1, :xmlElement))

  defp children(el, name), do: Enum.filter(element_children(el), &match?(element(name: ^name), &1))

  defp attr(element(attributes: attrs), name) do
    Enum.find_value(attrs, fn
      attribute(name: ^name, value: value) -> List.to_string(value)
      _ -> nil
    end)
  end

  defp content(element(content: content)) do
    content
    |> Enum.map(fn
      text(value: v) -> List.to_string(v)
      _ -> ""
    end)
    |> Enum.join()
    |> String.trim()
  end

  defp description(el) do
    case children(el, :description) do
      [d | _] -> d |> content() |> String.replace(~r/\s+/, " ")
      [] -> ""
    end
  end
end
