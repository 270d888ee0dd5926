defmodule Dolphin.MAVLink.Value do
  @moduledoc """
  How MAVLink field values look in Elixir, and the per-value conversions the
  generated message modules call.

  | wire type | Elixir value |
  | --- | --- |
  | `uint8_t` … `int64_t` | integer, exact (`uint64_t` up to 18446744073709551615) |
  | `float`, `double` | float (`-0.0` is kept), or a special value below |
  | `char[N]` | binary: the bytes up to the first NUL (all N when there is none) |
  | `T[N]` | list of exactly N elements (shorter lists are zero-padded on encode) |

  BEAM floats cannot hold NaN or infinities, so those decode to atoms, and each
  encodes back to the same bytes:

  | value | float bits written (`float` / `double`) |
  | --- | --- |
  | `:infinity` | `0x7F800000` / `0x7FF0000000000000` |
  | `:neg_infinity` | `0xFF800000` / `0xFFF0000000000000` |
  | `:nan` | the canonical quiet NaN `0x7FC00000` / `0x7FF8000000000000` |
  | `{:nan, bits}` | any other NaN, `bits` being its raw IEEE 754 pattern |

  A `float` field given a number beyond float32's range encodes as an infinity,
  as a C cast does.
  """

  import Bitwise

  alias Dolphin.MAVLink.FieldError

  @typedoc "A `float` or `double` field's value."
  @type float_value :: float() | :nan | :infinity | :neg_infinity | {:nan, non_neg_integer()}

  @typedoc "Base types of fields, as `Dolphin.MAVLink.XML` names them."
  @type base_type :: Dolphin.MAVLink.XML.base_type()

  @zeros :binary.copy(<<0>>, 256)

  @doc false
  # `n` zero bytes (n <= 256; a payload is at most 255): taken from a literal,
  # because a `0::size(n * 8)` segment wider than 64 bits is built bit by bit.
  @spec zeros(0..256) :: binary()
  def zeros(n), do: binary_part(@zeros, 0, n)

  @doc "Size in bytes of one value of a base type."
  @spec size(base_type()) :: 1 | 2 | 4 | 8
  def size(t) when t in [:uint8, :int8, :char], do: 1
  def size(t) when t in [:uint16, :int16], do: 2
  def size(t) when t in [:uint32, :int32, :float], do: 4
  def size(t) when t in [:uint64, :int64, :double], do: 8

  @doc "The inclusive range of an integer type."
  @spec int_range(base_type()) :: {integer(), integer()}
  def int_range(:uint8), do: {0, 0xFF}
  def int_range(:int8), do: {-0x80, 0x7F}
  def int_range(:uint16), do: {0, 0xFFFF}
  def int_range(:int16), do: {-0x8000, 0x7FFF}
  def int_range(:uint32), do: {0, 0xFFFF_FFFF}
  def int_range(:int32), do: {-0x8000_0000, 0x7FFF_FFFF}
  def int_range(:uint64), do: {0, 0xFFFF_FFFF_FFFF_FFFF}
  def int_range(:int64), do: {-0x8000_0000_0000_0000, 0x7FFF_FFFF_FFFF_FFFF}

  @doc "The zero value of a field (what a missing or truncated field decodes to)."
  @spec zero(base_type(), pos_integer() | nil) :: term()
  def zero(:char, _n), do: ""
  def zero(type, nil), do: scalar_zero(type)
  def zero(type, n), do: List.duplicate(scalar_zero(type), n)

  defp scalar_zero(t) when t in [:float, :double], do: 0.0
  defp scalar_zero(_int), do: 0

  @doc false
  # Decodes one field from exactly its bytes (generated decoders call it for
  # floats that may be NaN or infinite, which a float segment cannot match).
  @spec decode(base_type(), pos_integer() | nil, binary()) :: term()
  def decode(:char, _n, bytes), do: cstring(bytes)
  def decode(type, nil, bytes), do: decode_scalar(type, bytes)
  def decode(type, _n, bytes), do: decode_array(type, bytes)

  @doc false
  @spec cstring(binary()) :: binary()
  def cstring(bytes) do
    case :binary.match(bytes, <<0>>) do
      :nomatch -> bytes
      {pos, _} -> binary_part(bytes, 0, pos)
    end
  end

  @doc false
  @spec decode_array(base_type(), binary()) :: list()
  def decode_array(:uint8, bytes), do: :binary.bin_to_list(bytes)
  def decode_array(:int8, bytes), do: for(<<v::signed-8 <- bytes>>, do: v)
  def decode_array(:uint16, bytes), do: for(<<v::little-16 <- bytes>>, do: v)
  def decode_array(:int16, bytes), do: for(<<v::little-signed-16 <- bytes>>, do: v)
  def decode_array(:uint32, bytes), do: for(<<v::little-32 <- bytes>>, do: v)
  def decode_array(:int32, bytes), do: for(<<v::little-signed-32 <- bytes>>, do: v)
  def decode_array(:uint64, bytes), do: for(<<v::little-64 <- bytes>>, do: v)
  def decode_array(:int64, bytes), do: for(<<v::little-signed-64 <- bytes>>, do: v)
  # Bit-string generators skip elements whose pattern fails, so floats go through
  # bits: a NaN element must not vanish from the list.
  def decode_array(:float, bytes), do: for(<<v::binary-4 <- bytes>>, do: decode_scalar(:float, v))
  def decode_array(:double, bytes), do: for(<<v::binary-8 <- bytes>>, do: decode_scalar(:double, v))

  defp decode_scalar(:uint8, <<v>>), do: v
  defp decode_scalar(:int8, <<v::signed>>), do: v
  defp decode_scalar(:uint16, <<v::little-16>>), do: v
  defp decode_scalar(:int16, <<v::little-signed-16>>), do: v
  defp decode_scalar(:uint32, <<v::little-32>>), do: v
  defp decode_scalar(:int32, <<v::little-signed-32>>), do: v
  defp decode_scalar(:uint64, <<v::little-64>>), do: v
  defp decode_scalar(:int64, <<v::little-signed-64>>), do: v
  defp decode_scalar(:float, <<v::little-float-32>>), do: v
  defp decode_scalar(:float, <<bits::little-32>>), do: special(bits, 0x7F800000, 0x7FC00000, 31)
  defp decode_scalar(:double, <<v::little-float-64>>), do: v

  defp decode_scalar(:double, <<bits::little-64>>),
    do: special(bits, 0x7FF0000000000000, 0x7FF8000000000000, 63)

  # Exponent all ones: an infinity when the mantissa is zero, else a NaN.
  defp special(bits, inf, quiet_nan, sign_bit) do
    cond do
      bits == inf -> :infinity
      bits == bor(inf, 1 <<< sign_bit) -> :neg_infinity
      bits == quiet_nan -> :nan
      true -> {:nan, bits}
    end
  end

  @doc false
  # Encodes one field to exactly its bytes, or returns {:error, %FieldError{}}
  # for the value alone (the caller knows the message and the field).
  @spec encode(base_type(), pos_integer() | nil, term()) :: {:ok, binary()} | {:error, FieldError.t()}
  def encode(type, n, value) do
    case encode_value(type, n, value) do
      {:ok, bytes} -> {:ok, bytes}
      {:error, why} -> {:error, %FieldError{reason: :bad_value, value: value, detail: why}}
    end
  end

  defp encode_value(:char, n, value) do
    n = n || 1

    cond do
      not is_binary(value) -> {:error, "expected a binary of at most #{n} bytes"}
      byte_size(value) > n -> {:error, "longer than #{n} bytes"}
      true -> {:ok, <<value::binary, zeros(n - byte_size(value))::binary>>}
    end
  end

  defp encode_value(type, nil, value), do: encode_scalar(type, value)

  defp encode_value(type, n, values) when is_list(values) do
    if length(values) > n do
      {:error, "expected at most #{n} elements"}
    else
      values
      |> Enum.concat(List.duplicate(scalar_zero(type), n - length(values)))
      |> Enum.reduce_while({:ok, []}, fn v, {:ok, acc} ->
        case encode_scalar(type, v) do
          {:ok, bin} -> {:cont, {:ok, [acc | bin]}}
          {:error, why} -> {:halt, {:error, "element #{inspect(v)}: " <> why}}
        end
      end)
      |> case do
        {:ok, iodata} -> {:ok, IO.iodata_to_binary(iodata)}
        error -> error
      end
    end
  end

  defp encode_value(_type, n, _value), do: {:error, "expected a list of at most #{n} elements"}

  @doc false
  # Bytes of a float or double value, special values included; :error otherwise.
  @spec float_bytes(:float | :double, term()) :: binary() | :error
  def float_bytes(type, value) do
    case encode_scalar(type, value) do
      {:ok, bytes} -> bytes
      {:error, _} -> :error
    end
  end

  @doc false
  # The generated encoders' fast path for arrays: exactly `n` plain values
  # (numbers in range), else :error and the caller takes the general path,
  # which pads short lists, writes NaN/infinities and explains bad values.
  @spec pack_array(base_type(), pos_integer(), term()) :: binary() | :error
  def pack_array(:uint8, n, list) when is_list(list) and length(list) == n do
    # list_to_binary/1 would also take binaries and nested lists as elements.
    if bytes?(list), do: :erlang.list_to_binary(list), else: :error
  end

  def pack_array(type, n, list) when is_list(list) and length(list) == n, do: pack(type, list, [])
  def pack_array(_type, _n, _list), do: :error

  # Element bytes are gathered as iodata and joined once: appending to a
  # binary in a loop starts by allocating a writable binary, which costs more
  # than a short array.
  for {type, bits, min, max} <- [
        {:int8, 8, -0x80, 0x7F},
        {:uint16, 16, 0, 0xFFFF},
        {:int16, 16, -0x8000, 0x7FFF},
        {:uint32, 32, 0, 0xFFFF_FFFF},
        {:int32, 32, -0x8000_0000, 0x7FFF_FFFF},
        {:uint64, 64, 0, 0xFFFF_FFFF_FFFF_FFFF},
        {:int64, 64, -0x8000_0000_0000_0000, 0x7FFF_FFFF_FFFF_FFFF}
      ] do
    defp pack(unquote(type), [v | rest], acc) when is_integer(v) and v >= unquote(min) and v <= unquote(max),
      do: pack(unquote(type), rest, [acc | <<v::little-size(unquote(bits))>>])
  end

  defp bytes?([b | rest]) when is_integer(b) and b >= 0 and b <= 255, do: bytes?(rest)
  defp bytes?([]), do: true
  defp bytes?(_), do: false

  defp pack(:float, [v | rest], acc) when is_number(v), do: pack(:float, rest, [acc | <<v::little-float-32>>])
  defp pack(:double, [v | rest], acc) when is_number(v), do: pack(:double, rest, [acc | <<v::little-float-64>>])
  defp pack(_type, [], acc), do: IO.iodata_to_binary(acc)
  defp pack(_type, _bad, _acc), do: :error

  defp encode_scalar(type, v) when type in [:float, :double] do
    bits = size(type) * 8

    case v do
      v when is_number(v) -> {:ok, <<v::little-float-size(bits)>>}
      :nan when bits == 32 -> {:ok, <<0x7FC00000::little-32>>}
      :nan -> {:ok, <<0x7FF8000000000000::little-64>>}
      :infinity when bits == 32 -> {:ok, <<0x7F800000::little-32>>}
      :infinity -> {:ok, <<0x7FF0000000000000::little-64>>}
      :neg_infinity when bits == 32 -> {:ok, <<0xFF800000::little-32>>}
      :neg_infinity -> {:ok, <<0xFFF0000000000000::little-64>>}
      {:nan, nan} when is_integer(nan) and nan >= 0 and nan < 1 <<< bits -> {:ok, <<nan::little-size(bits)>>}
      _ -> {:error, "expected a number, :nan, :infinity, :neg_infinity or {:nan, bits}"}
    end
  end

  defp encode_scalar(type, v) do
    {min, max} = int_range(type)

    if is_integer(v) and v >= min and v <= max,
      do: {:ok, <<v::little-size(size(type) * 8)>>},
      else: {:error, "expected an integer in #{min}..#{max}"}
  end
end
