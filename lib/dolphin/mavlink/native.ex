defmodule Dolphin.MAVLink.Native do
  @moduledoc """
  The codec's fast path in C (`c_src/dolphin_native.c`), for what a healthy
  link carries: one call checks and decodes every frame of a buffer, from
  an offset, that is whole, unsigned, of a message the dialect defines and
  whose checksum holds, and stops at the first that is anything else.
  `Dolphin.MAVLink.Parser` then takes that one in Elixir (it resynchronises,
  verifies signatures, forwards or refuses unknown ids, and counts what it
  drops) and calls again after it. The frames are the terms
  `Dolphin.MAVLink.Frame.decode/3` builds, field for field (a property test
  decodes random streams both ways).

  Why: the Elixir decoder spent its time per frame on the checksum call, on
  each float (a runtime call each) and on building the two structs, and
  decoded the benchmark's telemetry at about 0.6 of the speed of the MAVLink
  C library; see docs/benchmarks.md for the figures before and after.

  Each dialect's messages are put in a table once (`for_dialect/1`, kept in
  `:persistent_term`). Without a C compiler the library is not built:
  `available?/0` is false and the parser decodes in Elixir alone, as before.
  """

  alias Dolphin.MAVLink.{Frame, Value}

  @types %{char: 0, uint8: 1, int8: 2, uint16: 3, int16: 4, uint32: 5, int32: 6, uint64: 7, int64: 8, float: 9, double: 10}

  @on_load :load_native
  defp load_native do
    with dir when is_list(dir) <- :code.priv_dir(:dolphin),
         {:error, {reason, text}} when reason != :reload <- :erlang.load_nif(:filename.join(dir, ~c"dolphin_native"), 0) do
      if reason != :load_failed or File.exists?(Path.join(dir, "dolphin_native.so")),
        do: :error_logger.warning_msg(~c"MAVLink codec in Erlang only: ~ts~n", [text])
    end

    :ok
  end

  @typedoc "A dialect's messages as the C library reads them."
  @opaque table :: reference()

  @doc "Whether the C library is loaded (else the parser decodes in Elixir alone)."
  @spec available?() :: boolean()
  def available?, do: is_reference(__MODULE__.table([]))

  @doc """
  The table of `dialect`'s messages, built on first use and kept; nil when
  the C library is not loaded.
  """
  @spec for_dialect(module()) :: table() | nil
  def for_dialect(dialect) do
    key = {__MODULE__, dialect}

    case :persistent_term.get(key, :none) do
      :none ->
        table = __MODULE__.table(specs(dialect))
        :persistent_term.put(key, table)
        table

      table ->
        table
    end
  end

  # Each message the dialect decodes, as its frame decoder gives it (so that
  # both paths know the same ids, CRC_EXTRA and lengths): id, CRC_EXTRA,
  # length, module, and each field in the order of its definition (the
  # order of `__from_values__/1`) with its type, array length (0: a scalar)
  # and offset in the payload (from the wire order).
  defp specs(dialect) do
    for module <- dialect.messages(),
        id = module.__mavlink__(:id),
        {crc_extra, max_len, _decode} <- [dialect.frame_decoder(id)] do
      {wire, _end} =
        Enum.map_reduce(module.__mavlink__(:wire), 0, fn {name, type, count}, offset ->
          {{name, {Map.fetch!(@types, type), count || 0, offset}}, offset + Value.size(type) * (count || 1)}
        end)

      wire = Map.new(wire)
      {id, crc_extra, max_len, module, Enum.map(module.__mavlink__(:fields), &Map.fetch!(wire, &1.name))}
    end
  end

  @doc false
  # The C library's table of messages, or nil without it.
  @spec table(list()) :: table() | nil
  def table(_messages), do: nil

  @doc """
  Decodes the frames of `binary` from `offset` while each is whole,
  unsigned, of a message of `table` and with a good checksum (at most 512
  in one call), consing them onto `acc` (newest first, as the parser
  gathers them). Returns `{acc, next_offset, count}`.
  """
  @spec decode(binary(), non_neg_integer(), table(), [Frame.t()]) :: {[Frame.t()], non_neg_integer(), non_neg_integer()}
  def decode(binary, offset, table, acc) do
    {decoded, next} = __MODULE__.native_decode(binary, offset, table)
    {acc, count} = frames(decoded, acc, 0)
    {acc, next, count}
  end

  defp frames([], acc, count), do: {acc, count}

  defp frames([{module, values, version, sysid, compid, seq, msgid, compat, payload, raw} | rest], acc, count),
    do: frames(rest, [Frame.new(Frame, version, 0, compat, seq, sysid, compid, msgid, module.__from_values__(values), payload, nil, raw) | acc], count + 1)

  @doc false
  # The C library's decoding: {frames, next_offset}, each frame {module,
  # field values, version, sysid, compid, seq, msgid, compat_flags, payload,
  # raw}. (Called by its full name, as table/1 is: the compiler must not
  # take these stubs for what the module's functions return.)
  def native_decode(_binary, _offset, _table), do: :erlang.nif_error(:not_loaded)
end
