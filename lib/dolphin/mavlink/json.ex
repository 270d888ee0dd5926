defmodule Dolphin.MAVLink.JSON do
  @moduledoc """
  Exact JSON for MAVLink records: numbers read and written without losing a bit.

  Why not jiffy (Debian's erlang-jiffy 1.1.1) for these: it reads the smallest
  subnormal doubles wrongly (`"5e-324"` becomes `0.0`), writes `-0.0` as `0.0`,
  and does not keep object key order. Here integers are exact at any size,
  floats go through `:erlang.binary_to_float/1` (correctly rounded) and are
  written as the shortest decimal that reads back to the same float, and objects
  keep their order as `{:object, [{key, value}]}` on write. On read, objects
  become maps.

      iex> Dolphin.MAVLink.JSON.decode(~s({"a": [-0.0, 5e-324, 18446744073709551615]}))
      {:ok, %{"a" => [-0.0, 5.0e-324, 18446744073709551615]}}
      iex> IO.iodata_to_binary(Dolphin.MAVLink.JSON.encode({:object, [{"b", -0.0}, {"a", "x"}]}))
      ~s({"b":-0.0,"a":"x"})
  """

  alias Dolphin.MAVLink.JSONError

  @type value :: map() | list() | String.t() | number() | boolean() | nil

  @doc "Parses one JSON text. Errors say what was found where (byte offset)."
  @spec decode(binary()) :: {:ok, value()} | {:error, JSONError.t()}
  def decode(text) when is_binary(text) do
    case value(skip_ws(text), text) do
      {:ok, v, rest} ->
        case skip_ws(rest) do
          <<>> -> {:ok, v}
          rest -> error(:trailing_data, rest, text)
        end

      {:error, _} = error ->
        error
    end
  end

  defp value(<<?{, rest::binary>>, text), do: object(skip_ws(rest), text, [])
  defp value(<<?[, rest::binary>>, text), do: array(skip_ws(rest), text, [])
  defp value(<<?", rest::binary>>, text), do: string(rest, text, [])
  defp value(<<"true", rest::binary>>, _text), do: {:ok, true, rest}
  defp value(<<"false", rest::binary>>, _text), do: {:ok, false, rest}
  defp value(<<"null", rest::binary>>, _text), do: {:ok, nil, rest}
  defp value(<<c, _::binary>> = bin, text) when c == ?- or c in ?0..?9, do: number(bin, text)
  defp value(rest, text), do: error(:expected_value, rest, text)

  defp object(<<?}, rest::binary>>, _text, []), do: {:ok, %{}, rest}

  defp object(<<?", rest::binary>>, text, acc) do
    with {:ok, key, rest} <- string(rest, text, []),
         <<?:, rest::binary>> <- skip_ws(rest),
         {:ok, v, rest} <- value(skip_ws(rest), text) do
      case skip_ws(rest) do
        <<?,, rest::binary>> -> object(skip_ws(rest), text, [{key, v} | acc])
        <<?}, rest::binary>> -> {:ok, Map.new(Enum.reverse([{key, v} | acc])), rest}
        rest -> error(:object_separator, rest, text)
      end
    else
      {:error, _} = error -> error
      rest -> error(:object_colon, rest, text)
    end
  end

  defp object(rest, text, _acc), do: error(:object_key, rest, text)

  defp array(<<?], rest::binary>>, _text, []), do: {:ok, [], rest}

  defp array(bin, text, acc) do
    with {:ok, v, rest} <- value(bin, text) do
      case skip_ws(rest) do
        <<?,, rest::binary>> -> array(skip_ws(rest), text, [v | acc])
        <<?], rest::binary>> -> {:ok, Enum.reverse([v | acc]), rest}
        rest -> error(:array_separator, rest, text)
      end
    end
  end

  defp string(<<?", rest::binary>>, _text, acc), do: {:ok, IO.iodata_to_binary(Enum.reverse(acc)), rest}

  defp string(<<?\\, c, rest::binary>>, text, acc) when c in ~c(\"\\/bfnrt) do
    char = %{?" => ?", ?\\ => ?\\, ?/ => ?/, ?b => ?\b, ?f => ?\f, ?n => ?\n, ?r => ?\r, ?t => ?\t}
    string(rest, text, [Map.fetch!(char, c) | acc])
  end

  defp string(<<"\\u", hi::binary-4, "\\u", lo::binary-4, rest::binary>> = bin, text, acc) do
    with {:ok, h} when h in 0xD800..0xDBFF <- hex4(hi),
         {:ok, l} when l in 0xDC00..0xDFFF <- hex4(lo) do
      string(rest, text, [<<0x10000 + (h - 0xD800) * 0x400 + (l - 0xDC00)::utf8>> | acc])
    else
      _ -> escape_u(bin, text, acc)
    end
  end

  defp string(<<"\\u", _::binary>> = bin, text, acc), do: escape_u(bin, text, acc)

  defp string(<<c, rest::binary>>, text, acc) when c >= 0x20 and c != ?\\, do: string(rest, text, [c | acc])
  defp string(rest, text, _acc), do: error(:string_character, rest, text)

  # \u00XX stands for the byte XX in our records (char[N] fields are bytes);
  # higher code points are written as UTF-8.
  defp escape_u(<<"\\u", hex::binary-4, rest::binary>> = bin, text, acc) do
    case hex4(hex) do
      {:ok, cp} when cp < 0x100 -> string(rest, text, [cp | acc])
      {:ok, cp} when cp in 0xD800..0xDFFF -> error(:lone_surrogate, bin, text)
      {:ok, cp} -> string(rest, text, [<<cp::utf8>> | acc])
      :error -> error(:bad_escape, bin, text)
    end
  end

  defp escape_u(bin, text, _acc), do: error(:bad_escape, bin, text)

  # Exactly four hex digits (Integer.parse/2 would take a sign too).
  defp hex4(<<a, b, c, d>> = hex) do
    if Enum.all?([a, b, c, d], &(&1 in ?0..?9 or &1 in ?a..?f or &1 in ?A..?F)),
      do: {:ok, String.to_integer(hex, 16)},
      else: :error
  end

  defp number(bin, text) do
    case Regex.run(~r/\A(-?(?:0|[1-9][0-9]*))(?:\.([0-9]+))?(?:[eE]([+-]?[0-9]+))?/, bin) do
      [whole, int] ->
        {:ok, String.to_integer(int), binary_part(bin, byte_size(whole), byte_size(bin) - byte_size(whole))}

      [whole, int | parts] ->
        frac = Enum.at(parts, 0, "")
        exp = Enum.at(parts, 1, "")
        frac = if frac == "", do: "0", else: frac
        exp = if exp == "", do: "0", else: String.trim_leading(exp, "+")
        rest = binary_part(bin, byte_size(whole), byte_size(bin) - byte_size(whole))

        try do
          {:ok, :erlang.binary_to_float(int <> "." <> frac <> "e" <> exp), rest}
        rescue
          ArgumentError -> error(:number_range, bin, text)
        end

      nil ->
        error(:bad_number, bin, text)
    end
  end

  defp skip_ws(<<c, rest::binary>>) when c in ~c( \t\r\n), do: skip_ws(rest)
  defp skip_ws(bin), do: bin

  defp error(reason, rest, text) do
    found = if rest == <<>>, do: nil, else: binary_part(rest, 0, min(12, byte_size(rest)))
    {:error, %JSONError{reason: reason, position: byte_size(text) - byte_size(rest), found: found}}
  end

  @doc """
  Writes a value as JSON iodata. Objects are `{:object, [{key, value}]}` (kept in
  order) or maps; `:nan`, `:infinity` and `:neg_infinity` (and `{:nan, bits}`)
  become the strings `"NaN"`, `"Infinity"`, `"-Infinity"`; strings are bytes:
  printable ASCII as is, every other byte as `\\u00XX`.
  """
  @spec encode(term()) :: iodata()
  def encode({:object, pairs}) do
    ["{", pairs |> Enum.map(fn {k, v} -> [encode_string(to_string(k)), ":", encode(v)] end) |> Enum.intersperse(","), "}"]
  end

  def encode(%{} = map), do: encode({:object, Enum.sort(Map.to_list(map))})
  def encode(list) when is_list(list), do: ["[", list |> Enum.map(&encode/1) |> Enum.intersperse(","), "]"]
  def encode(true), do: "true"
  def encode(false), do: "false"
  def encode(nil), do: "null"
  def encode(int) when is_integer(int), do: Integer.to_string(int)
  def encode(float) when is_float(float), do: :erlang.float_to_binary(float, [:short])
  def encode(:nan), do: ~s("NaN")
  def encode({:nan, _bits}), do: ~s("NaN")
  def encode(:infinity), do: ~s("Infinity")
  def encode(:neg_infinity), do: ~s("-Infinity")
  def encode(atom) when is_atom(atom), do: encode_string(Atom.to_string(atom))
  def encode(bin) when is_binary(bin), do: encode_string(bin)

  defp encode_string(bin) do
    escaped =
      for <<byte <- bin>> do
        case byte do
          ?" -> "\\\""
          ?\\ -> "\\\\"
          b when b >= 0x20 and b < 0x7F -> b
          b -> "\\u00" <> Base.encode16(<<b>>, case: :lower)
        end
      end

    [?", escaped, ?"]
  end
end
