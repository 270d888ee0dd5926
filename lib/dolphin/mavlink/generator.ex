defmodule Dolphin.MAVLink.Generator do
  @moduledoc """
  Turns dialect definitions (`Dolphin.MAVLink.XML`) into code, in two pure steps:

    1. `message_specs/2`: per message, plain data — module name, fields in XML
       and in wire order, CRC_EXTRA, MAVLink 1 and 2 payload lengths;
    2. `message_module/1` and `dialect_functions/2`: quoted Elixir (never
       strings) that `Dolphin.MAVLink.Dialect` injects at compile time.

  Wire order is the MAVLink rule: non-extension fields sorted by the size of
  their base type, largest first, keeping XML order among equals; extension
  fields follow in XML order. CRC_EXTRA is seeded from the name and the
  non-extension fields in wire order, as mavgen does.

  Each generated message module has two decode and two encode clauses: a fast
  one that matches or builds the whole payload in one binary pattern, and a
  general one (`Dolphin.MAVLink.Message`) that the fast one falls through to
  for what a pattern cannot express (NaN and infinite floats) and that reports
  bad values field by field.
  """

  alias Dolphin.MAVLink.{CRC, Value}

  @type field :: %{
          name: atom(),
          type: Value.base_type(),
          array_length: pos_integer() | nil,
          enum: atom() | nil,
          units: String.t() | nil,
          extension: boolean(),
          default: term(),
          description: String.t()
        }

  @type spec :: %{
          id: non_neg_integer(),
          name: String.t(),
          module: module(),
          dialect: module(),
          description: String.t(),
          crc_extra: byte(),
          min_len: non_neg_integer(),
          max_len: non_neg_integer(),
          fields: [field()],
          wire: [field()]
        }

  @doc "Per-message specs of a dialect, with message modules nested under `dialect`."
  @spec message_specs(Dolphin.MAVLink.XML.definitions(), module()) :: [spec()]
  def message_specs(%{messages: messages}, dialect) do
    Enum.map(messages, &message_spec(&1, dialect))
  end

  @doc """
  Why a message of a user's dialect cannot be added to generated dialect
  `base` (ArduPilot's): its id is another message's there; `nil` when it can.

      iex> Dolphin.MAVLink.Generator.taken_id(%{id: 0, name: "MY_BEAT"}, Dolphin.MAVLink.Ardupilotmega)
      "MY_BEAT has id 0, which ardupilotmega's HEARTBEAT has"
      iex> Dolphin.MAVLink.Generator.taken_id(%{id: 42_999, name: "SMOKE"}, Dolphin.MAVLink.Ardupilotmega)
      nil
  """
  @spec taken_id(%{id: non_neg_integer(), name: String.t()}, module()) :: String.t() | nil
  def taken_id(%{id: id, name: name}, base) do
    case base.message_info(id) do
      nil -> nil
      {taken, _, _, _} -> "#{name} has id #{id}, which #{base |> Module.split() |> List.last() |> String.downcase()}'s #{taken.__mavlink__(:name)} has"
    end
  end

  defp message_spec(msg, dialect) do
    fields = Enum.map(msg.fields, &field/1)
    wire = wire_order(fields)
    base = Enum.reject(wire, & &1.extension)

    %{
      id: msg.id,
      name: msg.name,
      module: Module.concat(dialect, module_name(msg.name)),
      dialect: dialect,
      description: msg.description,
      crc_extra: CRC.crc_extra(msg.name, Enum.map(base, &{c_type(&1.type), Atom.to_string(&1.name), &1.array_length})),
      min_len: payload_size(base),
      max_len: payload_size(wire),
      fields: fields,
      wire: wire
    }
  end

  defp field(f) do
    %{
      name: String.to_atom(f.name),
      type: f.type,
      array_length: f.array_length,
      enum: f.enum && enum_atom(f.enum),
      units: f.units,
      extension: f.extension,
      # HEARTBEAT.mavlink_version: what a sender fills in when not told otherwise.
      default: if(f.mavlink_version, do: 3, else: Value.zero(f.type, f.array_length)),
      description: f.description
    }
  end

  @doc "Fields in wire order: base fields by descending type size (stable), then extensions."
  @spec wire_order([field()]) :: [field()]
  def wire_order(fields) do
    {extensions, base} = Enum.split_with(fields, & &1.extension)
    Enum.sort_by(base, &Value.size(&1.type), :desc) ++ extensions
  end

  defp payload_size(fields), do: Enum.reduce(fields, 0, &(&2 + field_size(&1)))

  defp field_size(f), do: Value.size(f.type) * (f.array_length || 1)

  defp c_type(:char), do: "char"
  defp c_type(:float), do: "float"
  defp c_type(:double), do: "double"
  defp c_type(int), do: Atom.to_string(int) <> "_t"

  @doc ~S'Module name of a message: `"GLOBAL_POSITION_INT"` -> `"GlobalPositionInt"`.'
  @spec module_name(String.t()) :: String.t()
  def module_name(name), do: name |> String.downcase() |> Macro.camelize()

  @doc ~S'Atom naming an enum or an enum entry: `"MAV_TYPE_QUADROTOR"` -> `:mav_type_quadrotor`.'
  @spec enum_atom(String.t()) :: atom()
  def enum_atom(name), do: name |> String.downcase() |> String.to_atom()

  ## Message modules

  @doc "The quoted `defmodule` of one message."
  @spec message_module(spec()) :: Macro.t()
  def message_module(spec) do
    quote do
      defmodule unquote(spec.module) do
        @moduledoc unquote(moduledoc(spec))
        @behaviour Dolphin.MAVLink.Message

        defstruct unquote(Macro.escape(Enum.map(spec.fields, &{&1.name, &1.default})))

        @type t :: %__MODULE__{unquote_splicing(Enum.map(spec.fields, &{&1.name, field_type(&1)}))}

        @doc false
        @impl true
        def __mavlink__(:id), do: unquote(spec.id)
        def __mavlink__(:name), do: unquote(spec.name)
        def __mavlink__(:crc_extra), do: unquote(spec.crc_extra)
        def __mavlink__(:min_len), do: unquote(spec.min_len)
        def __mavlink__(:max_len), do: unquote(spec.max_len)
        def __mavlink__(:dialect), do: unquote(spec.dialect)
        def __mavlink__(:fields), do: unquote(Macro.escape(spec.fields))
        def __mavlink__(:wire), do: unquote(Macro.escape(Enum.map(spec.wire, &{&1.name, &1.type, &1.array_length})))

        @doc false
        # What Dolphin.MAVLink.Frame.encode/2 needs, in one call: `{id,
        # crc_extra, min_len, payload}`.
        def __frame__(message), do: {unquote(spec.id), unquote(spec.crc_extra), unquote(spec.min_len), encode(message)}

        unquote(decode_clauses(spec))
        unquote(encode_clauses(spec))
      end
    end
  end

  defp moduledoc(spec) do
    rows =
      Enum.map(spec.fields, fn f ->
        type = if f.array_length, do: "#{f.type}[#{f.array_length}]", else: "#{f.type}"
        extra = Enum.reject([f.units && "units: #{f.units}", f.enum && "enum: `#{inspect(f.enum)}`", f.extension && "extension"], &(&1 in [nil, false]))
        "| `#{f.name}` | #{type} | #{Enum.join(extra, ", ")} | #{String.replace(f.description, "|", "\\|")} |"
      end)

    """
    MAVLink message #{spec.name} (id #{spec.id}, CRC_EXTRA #{spec.crc_extra}, payload #{spec.min_len}..#{spec.max_len} bytes).

    #{spec.description}

    | field | type | | description |
    | --- | --- | --- | --- |
    #{Enum.join(rows, "\n")}
    """
  end

  defp field_type(%{type: :char}), do: quote(do: binary())
  defp field_type(%{array_length: nil, type: t}), do: scalar_type(t)
  defp field_type(%{type: t}), do: quote(do: [unquote(scalar_type(t))])

  defp scalar_type(t) when t in [:float, :double], do: quote(do: Dolphin.MAVLink.Value.float_value())
  defp scalar_type(:uint64), do: quote(do: non_neg_integer())
  defp scalar_type(:int64), do: quote(do: integer())

  defp scalar_type(t) do
    {min, max} = Value.int_range(t)
    quote(do: unquote(min)..unquote(max))
  end

  # decode/1 takes a payload of exactly max_len bytes (the frame layer zero-fills
  # truncated MAVLink 2 payloads and MAVLink 1 payloads without extensions).
  # The first clause matches floats with float segments, which fail on NaN and
  # infinities; the second (only for messages with scalar floats) takes their
  # bits and converts them, so every payload of the right size is decoded.
  #
  # The struct is built by new/N from the module passed as an argument: a
  # literal %__MODULE__{...} makes the compiler fold the module into a constant
  # map that each decode then updates key by key, which costs about twice as much.
  defp decode_clauses(spec) do
    fast = decode_clause(spec, false)
    struct = Macro.var(:struct__, __MODULE__)
    vars = Enum.map(spec.fields, &var/1)

    new =
      quote do
        defp new(unquote(struct), unquote_splicing(vars)) do
          %{unquote_splicing([{:__struct__, struct} | Enum.map(spec.fields, &{&1.name, var(&1)})])}
        end
      end

    # The struct from its field values in a tuple (definition order), as the
    # parser's C fast path decodes them (Dolphin.MAVLink.Native).
    from_values =
      quote do
        @doc false
        def __from_values__({unquote_splicing(vars)}), do: new(__MODULE__, unquote_splicing(vars))
      end

    if Enum.any?(spec.wire, &scalar_float?/1),
      do:
        quote(
          do:
            (
              unquote(fast)
              unquote(decode_clause(spec, true))
              unquote(from_values)
              unquote(new)
            )
        ),
      else:
        quote(
          do:
            (
              unquote(fast)
              unquote(from_values)
              unquote(new)
            )
        )
  end

  defp decode_clause(spec, floats_as_bits?) do
    segments = Enum.map(spec.wire, &decode_segment(&1, floats_as_bits?))
    values = Enum.map(spec.fields, &decode_value(&1, floats_as_bits?))

    quote do
      @doc false
      @impl true
      def decode(<<unquote_splicing(segments)>>), do: new(__MODULE__, unquote_splicing(values))
    end
  end

  defp scalar_float?(%{type: t, array_length: nil}), do: t in [:float, :double]
  defp scalar_float?(_), do: false

  defp decode_segment(%{type: t, array_length: n} = f, _bits?) when t == :char or n != nil do
    quote(do: unquote(var(f)) :: binary - size(unquote(field_size(f))))
  end

  defp decode_segment(%{type: t} = f, true) when t in [:float, :double] do
    quote(do: unquote(var(f)) :: binary - size(unquote(Value.size(t))))
  end

  defp decode_segment(%{type: t} = f, false) when t in [:float, :double] do
    quote(do: unquote(var(f)) :: little - float - size(unquote(Value.size(t) * 8)))
  end

  defp decode_segment(%{type: t} = f, _bits?) when t in [:int8, :int16, :int32, :int64] do
    quote(do: unquote(var(f)) :: little - signed - size(unquote(Value.size(t) * 8)))
  end

  defp decode_segment(%{type: t} = f, _bits?) do
    quote(do: unquote(var(f)) :: little - size(unquote(Value.size(t) * 8)))
  end

  defp decode_value(%{type: t, array_length: nil} = f, true) when t in [:float, :double],
    do: quote(do: Dolphin.MAVLink.Value.decode(unquote(t), nil, unquote(var(f))))

  defp decode_value(f, _bits?), do: decode_value(f)

  defp decode_value(%{type: :char} = f), do: quote(do: Dolphin.MAVLink.Value.cstring(unquote(var(f))))
  defp decode_value(%{array_length: nil} = f), do: var(f)
  defp decode_value(f), do: quote(do: Dolphin.MAVLink.Value.decode_array(unquote(f.type), unquote(var(f))))

  # encode/1 returns the full wire-ordered payload (max_len bytes); the frame
  # layer cuts it to MAVLink 1 length or truncates trailing zeros for MAVLink 2.
  # Like decoding: a first clause for plain numbers; a second, for messages
  # with scalar floats, that writes NaN and infinities through
  # Dolphin.MAVLink.Value; and a last one, the general encoder, which pads
  # short arrays and raises an ArgumentError naming a bad field.
  defp encode_clauses(spec) do
    # Not a plain `message` variable: a field could be called that.
    message = Macro.var(:message__, __MODULE__)
    floats = Enum.filter(spec.wire, &scalar_float?/1)

    specials =
      if floats != [] do
        encode_clause(spec, message, Enum.reject(spec.fields, &scalar_float?/1), floats)
      end

    quote do
      unquote(encode_clause(spec, message, spec.fields, []))
      unquote(specials)

      def encode(%__MODULE__{} = unquote(message)), do: Dolphin.MAVLink.Message.encode_fields!(unquote(message))
    end
  end

  defp encode_clause(spec, message, guarded, float_bits) do
    bindings = Enum.map(spec.fields, &{&1.name, var(&1)})
    guards = guarded |> Enum.map(&encode_guard/1) |> Enum.reduce(true, &quote(do: unquote(&2) and unquote(&1)))
    bits? = float_bits != []
    payload = quote(do: <<unquote_splicing(payload_segments(spec.wire, bits?))>>)

    # Arrays (and, in the second clause, floats) are converted first; anything
    # that does not convert sends the whole message down the general path.
    converts =
      for(f <- float_bits, do: {f, quote(do: Dolphin.MAVLink.Value.float_bytes(unquote(f.type), unquote(var(f))))}) ++
        for f <- spec.fields, f.array_length != nil and f.type != :char do
          {f, quote(do: Dolphin.MAVLink.Value.pack_array(unquote(f.type), unquote(f.array_length), unquote(var(f))))}
        end

    body =
      case converts do
        [] ->
          payload

        converts ->
          steps = for {f, call} <- converts, do: quote(do: unquote(var(f)) when is_binary(unquote(var(f))) <- unquote(call))

          quote do
            with unquote_splicing(steps) do
              unquote(payload)
            else
              _ -> Dolphin.MAVLink.Message.encode_fields!(unquote(message))
            end
          end
      end

    quote do
      @doc false
      @impl true
      def encode(%__MODULE__{unquote_splicing(bindings)} = unquote(message)) when unquote(guards) do
        _ = unquote(message)
        unquote(body)
      end
    end
  end

  defp encode_guard(%{type: :char} = f) do
    quote(do: is_binary(unquote(var(f))) and byte_size(unquote(var(f))) <= unquote(f.array_length || 1))
  end

  defp encode_guard(%{array_length: n} = f) when n != nil, do: quote(do: is_list(unquote(var(f))))

  defp encode_guard(%{type: t} = f) when t in [:float, :double], do: quote(do: is_number(unquote(var(f))))

  defp encode_guard(%{type: t} = f) do
    {min, max} = Value.int_range(t)
    v = var(f)
    quote(do: is_integer(unquote(v)) and unquote(v) >= unquote(min) and unquote(v) <= unquote(max))
  end

  # Adjacent integer fields are written as one segment when together they fit
  # in 56 bits (a small integer): on OTP 25 each integer segment of a binary
  # construction is a call into the runtime, which costs more than the shifts.
  # The clause's guards have checked every value's range; signed values are
  # masked to their two's complement bits.
  @packed_bits 56

  defp payload_segments(wire, bits?) do
    wire
    |> Enum.reduce([], fn f, acc ->
      case {packable_bits(f), acc} do
        {nil, acc} -> [f | acc]
        {bits, [{:packed, fs, total} | acc]} when total + bits <= @packed_bits -> [{:packed, [f | fs], total + bits} | acc]
        {bits, acc} -> [{:packed, [f], bits} | acc]
      end
    end)
    |> Enum.reverse()
    |> Enum.flat_map(fn
      {:packed, [f], _bits} -> encode_segments(f, bits?)
      {:packed, fs, total} -> [quote(do: unquote(packed_value(Enum.reverse(fs))) :: little - size(unquote(total)))]
      f -> encode_segments(f, bits?)
    end)
  end

  defp packable_bits(%{type: t, array_length: nil}) when t not in [:char, :float, :double, :uint64, :int64], do: Value.size(t) * 8
  defp packable_bits(_field), do: nil

  # The first field in the low bits: the segment is little-endian, like the fields.
  defp packed_value(fields) do
    {terms, _bits} =
      Enum.map_reduce(fields, 0, fn f, shift ->
        bits = Value.size(f.type) * 8
        v = if f.type in [:int8, :int16, :int32], do: quote(do: :erlang.band(unquote(var(f)), unquote(Bitwise.bsl(1, bits) - 1))), else: var(f)
        {if(shift == 0, do: v, else: quote(do: :erlang.bsl(unquote(v), unquote(shift)))), shift + bits}
      end)

    Enum.reduce(tl(terms), hd(terms), &quote(do: :erlang.bor(unquote(&2), unquote(&1))))
  end

  defp encode_segments(%{type: t, array_length: nil} = f, true) when t in [:float, :double],
    do: [quote(do: unquote(var(f)) :: binary)]

  defp encode_segments(f, _bits?), do: encode_segments(f)

  defp encode_segments(%{type: :char} = f) do
    v = var(f)
    n = f.array_length || 1
    [quote(do: unquote(v) :: binary), quote(do: Dolphin.MAVLink.Value.zeros(unquote(n) - byte_size(unquote(v))) :: binary)]
  end

  defp encode_segments(%{array_length: n} = f) when n != nil, do: [quote(do: unquote(var(f)) :: binary)]

  defp encode_segments(%{type: t} = f) when t in [:float, :double] do
    [quote(do: unquote(var(f)) :: little - float - size(unquote(Value.size(t) * 8)))]
  end

  defp encode_segments(%{type: t} = f) do
    [quote(do: unquote(var(f)) :: little - size(unquote(Value.size(t) * 8)))]
  end

  defp var(%{name: name}), do: Macro.var(name, __MODULE__)

  ## Dialect-wide functions

  @doc "Quoted functions of the dialect module: message look-ups and enums."
  @spec dialect_functions([spec()], [Dolphin.MAVLink.XML.enum()]) :: Macro.t()
  def dialect_functions(specs, enums) do
    info_clauses =
      for s <- specs do
        quote do
          def message_info(unquote(s.id)), do: unquote(Macro.escape({s.module, s.crc_extra, s.min_len, s.max_len}))
        end
      end

    decoder_clauses =
      for s <- specs do
        quote do
          def frame_decoder(unquote(s.id)), do: {unquote(s.crc_extra), unquote(s.max_len), &unquote(s.module).decode/1}
        end
      end

    by_name = Map.new(specs, &{&1.name, &1.module})
    modules = Enum.map(specs, & &1.module)

    enum_values = Map.new(enums, fn e -> {enum_atom(e.name), Map.new(e.entries, &{enum_atom(&1.name), &1.value})} end)

    enum_names = Map.new(enums, fn e -> {enum_atom(e.name), Map.new(e.entries, &{&1.value, enum_atom(&1.name)})} end)

    enum_entries = Map.new(enums, fn e -> {enum_atom(e.name), Enum.map(e.entries, &{enum_atom(&1.name), &1.value})} end)
    bitmasks = for e <- enums, e.bitmask, do: enum_atom(e.name)

    quote do
      @doc """
      `{module, crc_extra, min_len, max_len}` of a message id, or `nil` for an id
      this dialect does not define.
      """
      @spec message_info(non_neg_integer()) :: {module(), byte(), non_neg_integer(), non_neg_integer()} | nil
      unquote_splicing(info_clauses)
      def message_info(_id), do: nil

      @doc false
      # What Dolphin.MAVLink.Frame needs to check and decode a frame with this
      # id: `{crc_extra, max_len, decode_fun}`, or nil.
      unquote_splicing(decoder_clauses)
      def frame_decoder(_id), do: nil

      @doc "The module of a message by its XML name (`\"HEARTBEAT\"`), or `nil`."
      @spec message_module(String.t()) :: module() | nil
      def message_module(name), do: Map.get(unquote(Macro.escape(by_name)), name)

      @doc "Every message module of the dialect, by ascending id."
      @spec messages() :: [module()]
      def messages, do: unquote(modules)

      @doc "Every enum of the dialect, as atoms (`:mav_type`, `:mav_cmd`, ...)."
      @spec enums() :: [atom()]
      def enums, do: unquote(Map.keys(enum_entries))

      @doc "The entries of an enum as `{name, value}` in definition order (`[]` for an unknown enum)."
      @spec enum_entries(atom()) :: [{atom(), integer()}]
      def enum_entries(enum), do: Map.get(unquote(Macro.escape(enum_entries)), enum, [])

      @doc "The value of an enum entry: `enum_value(:mav_type, :mav_type_quadrotor)` -> `{:ok, 2}`."
      @spec enum_value(atom(), atom()) :: {:ok, integer()} | :error
      def enum_value(enum, entry) do
        with {:ok, entries} <- Map.fetch(unquote(Macro.escape(enum_values)), enum), do: Map.fetch(entries, entry)
      end

      @doc "The entry of an enum with a value: `enum_name(:mav_type, 2)` -> `{:ok, :mav_type_quadrotor}`."
      @spec enum_name(atom(), integer()) :: {:ok, atom()} | :error
      def enum_name(enum, value) do
        with {:ok, entries} <- Map.fetch(unquote(Macro.escape(enum_names)), enum), do: Map.fetch(entries, value)
      end

      @doc "Whether an enum is a bitmask (its values are OR-ed flags)."
      @spec bitmask?(atom()) :: boolean()
      def bitmask?(enum), do: enum in unquote(bitmasks)

      @doc """
      The flags of a bitmask enum set in `value`, and the bits no entry names:
      `enum_flags(:mav_mode_flag, 0x81)` -> `{[:mav_mode_flag_safety_armed, :mav_mode_flag_custom_mode_enabled], 0}`.
      """
      @spec enum_flags(atom(), non_neg_integer()) :: {[atom()], non_neg_integer()}
      def enum_flags(enum, value) do
        Enum.reduce(enum_entries(enum), {[], value}, fn {name, bit}, {set, rest} ->
          if bit != 0 and Bitwise.band(value, bit) == bit,
            do: {[name | set], Bitwise.band(rest, Bitwise.bnot(bit))},
            else: {set, rest}
        end)
        |> then(fn {set, rest} -> {Enum.reverse(set), rest} end)
      end
    end
  end
end
