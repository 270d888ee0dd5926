defmodule Dolphin.JSONText do
  @moduledoc """
  JSON files a user gives (a QGroundControl plan, ...) read with jiffy, and
  what is wrong with them said in the file's terms: where (line and column,
  counted from 1, and the byte) and what, rather than jiffy's
  `{byte, :truncated_json}`.

      iex> Dolphin.JSONText.decode(~s({"a": [1, 2]}))
      {:ok, %{"a" => [1, 2]}}
      iex> Dolphin.JSONText.decode(~s({\\n  "fileType": "Plan",\\n))
      {:error, "line 3, column 1 (byte 25): the text ends before the JSON value does"}
      iex> Dolphin.JSONText.decode(~s|{"a": tru}|)
      {:error, ~s|line 1, column 7 (byte 7): not true, false or null: "tru}"|}

  `show/1` writes a value of the decoded JSON back as JSON, for messages
  that quote what the file holds.
  """

  @doc """
  The JSON text's value (objects as maps, `null` as `:null`), or where and
  why it is not JSON.
  """
  @spec decode(binary()) :: {:ok, term()} | {:error, String.t()}
  def decode(text) when is_binary(text) do
    if String.trim(text) == "" do
      {:error, "the file is empty: no JSON value in it"}
    else
      try do
        {:ok, :jiffy.decode(text, [:return_maps])}
      catch
        # jiffy raises {byte, reason}, the byte counted from 1 (one past
        # the end when the text ends too early).
        kind, {at, reason} when kind in [:error, :throw] and is_integer(at) -> {:error, where(text, at) <> ": " <> what(reason, found(text, at))}
        kind, {:error, {at, reason}} when kind in [:error, :throw] and is_integer(at) -> {:error, where(text, at) <> ": " <> what(reason, found(text, at))}
      end
    end
  end

  @doc """
  A value of the decoded JSON as JSON text (cut at 60 characters).

      iex> Dolphin.JSONText.show(%{"command" => "abc", "frame" => :null})
      ~s({"command":"abc","frame":null})
      iex> Dolphin.JSONText.show([1, 2.5, true])
      "[1,2.5,true]"
  """
  @spec show(term()) :: String.t()
  def show(value) do
    text =
      try do
        IO.iodata_to_binary(:jiffy.encode(ordered(value)))
      catch
        _, _ -> inspect(value)
      end

    if String.length(text) > 60, do: String.slice(text, 0, 59) <> "…", else: text
  end

  # Keys in sorted order (jiffy keeps the order of a proplist).
  defp ordered(%{} = map), do: {map |> Enum.sort() |> Enum.map(fn {k, v} -> {k, ordered(v)} end)}
  defp ordered(list) when is_list(list), do: Enum.map(list, &ordered/1)
  defp ordered(other), do: other

  @doc """
  What kind of JSON value `value` is, in JSON's words.

      iex> Dolphin.JSONText.kind([])
      "an array"
  """
  @spec kind(term()) :: String.t()
  def kind(value) when is_map(value), do: "an object"
  def kind(value) when is_list(value), do: "an array"
  def kind(value) when is_binary(value), do: "a string"
  def kind(value) when is_number(value), do: "a number"
  def kind(value) when is_boolean(value), do: "#{value}"
  def kind(:null), do: "null"
  def kind(_value), do: "not JSON"

  @doc """
  The line (from 1) at which each value of valid JSON `text` begins, by its
  path from the top (object keys as strings, array indexes from 0; `[]` is
  the whole text): where to point a user at a value that is wrong.

      iex> Dolphin.JSONText.lines(~s({\\n  "fires": [\\n    {"lat": 40.1,\\n     "radius_m": -3}\\n  ]\\n}))[["fires", 0, "radius_m"]]
      4
  """
  @spec lines(binary()) :: %{[String.t() | non_neg_integer()] => pos_integer()}
  def lines(text) when is_binary(text) do
    {_rest, _line, found} = value(skip(text, 1), [], %{})
    found
  end

  # A small scanner of valid JSON: it follows lines and paths only (the
  # text was decoded already), noting where each value starts.
  defp value({rest, line}, path, found) do
    found = Map.put(found, Enum.reverse(path), line)

    case rest do
      "{" <> rest -> members(skip(rest, line), path, found)
      "[" <> rest -> elements(skip(rest, line), path, 0, found)
      "\"" <> rest -> {rest |> string() |> elem(1), line, found}
      _ -> {scalar(rest), line, found}
    end
  end

  defp members({"}" <> rest, line}, _path, found), do: {rest, line, found}

  defp members({"\"" <> rest, line}, path, found) do
    {key, rest} = string(rest)
    {":" <> rest, line} = skip(rest, line)
    {rest, line, found} = value(skip(rest, line), [key | path], found)

    case skip(rest, line) do
      {"," <> rest, line} -> members(skip(rest, line), path, found)
      {"}" <> rest, line} -> {rest, line, found}
    end
  end

  defp elements({"]" <> rest, line}, _path, _i, found), do: {rest, line, found}

  defp elements(at, path, i, found) do
    {rest, line, found} = value(at, [i | path], found)

    case skip(rest, line) do
      {"," <> rest, line} -> elements(skip(rest, line), path, i + 1, found)
      {"]" <> rest, line} -> {rest, line, found}
    end
  end

  # A string's text (escapes kept as written: keys are compared as written) and what follows.
  defp string(text), do: string(text, [])
  defp string("\\" <> <<c, rest::binary>>, acc), do: string(rest, [c, ?\\ | acc])
  defp string("\"" <> rest, acc), do: {acc |> Enum.reverse() |> IO.iodata_to_binary(), rest}
  defp string(<<c, rest::binary>>, acc), do: string(rest, [c | acc])

  defp scalar(text), do: String.replace(text, ~r/^[^,\]\}\s]+/, "", global: false)

  defp skip(<<c, rest::binary>>, line) when c in [?\s, ?\t, ?\r], do: skip(rest, line)
  defp skip("\n" <> rest, line), do: skip(rest, line + 1)
  defp skip(rest, line), do: {rest, line}

  # "line L, column C (byte B)": C counts characters from the line's start.
  defp where(text, at) do
    before = binary_part(text, 0, min(at - 1, byte_size(text)))
    lines = String.split(before, "\n")
    last = List.last(lines)
    column = if String.valid?(last), do: String.length(last) + 1, else: byte_size(last) + 1
    "line #{length(lines)}, column #{column} (byte #{at})"
  end

  defp found(text, at) when at > byte_size(text), do: nil

  defp found(text, at) do
    rest = binary_part(text, at - 1, byte_size(text) - at + 1)
    line = rest |> String.split("\n", parts: 2) |> hd()
    if String.valid?(line), do: String.slice(line, 0, 12), else: binary_part(line, 0, min(12, byte_size(line)))
  end

  defp what(:truncated_json, _found), do: "the text ends before the JSON value does"
  defp what(_reason, nil), do: "the text ends before the JSON value does"
  defp what(:invalid_literal, found), do: "not true, false or null: #{inspect(found)}"
  defp what(:invalid_number, found), do: "not a number: #{inspect(found)}"
  defp what(:invalid_string, found), do: "a bad string (a bad escape, or a control character in it): #{inspect(found)}"
  defp what(:invalid_trailing_data, found), do: "more after the end of the JSON value: #{inspect(found)}"
  defp what(_reason, found), do: "unexpected #{inspect(found)}"
end
