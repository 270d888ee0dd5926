defmodule Dolphin.Test.Vectors do
  @moduledoc """
  The shared MAVLink test vectors (`../shared/mavlink/vectors`, beside the
  project), read with the exact JSON reader.
  """

  @dir Path.expand("../../../shared/mavlink/vectors", __DIR__)

  @doc "The vectors' directory."
  def dir, do: @dir

  @doc "Path of a vectors file; fails the test with a clear message when missing."
  def path!(name) do
    path = Path.join(@dir, name)
    File.exists?(path) || raise "test vectors not found: #{path} (the shared/ folder must sit beside the project)"
    path
  end

  @doc "Records of a .jsonl file as `{line_number, raw_line, map}`."
  def records(name) do
    name
    |> path!()
    |> File.stream!()
    |> Stream.with_index(1)
    |> Enum.map(fn {line, n} ->
      {:ok, map} = Dolphin.MAVLink.JSON.decode(line)
      {n, line, map}
    end)
  end

  @doc """
  A signing state for reading the vectors' recorded traffic: their timestamps
  are in the past (replay window from 0) and the stream mixes unsigned frames.
  """
  def signing, do: Dolphin.MAVLink.Signing.new(key: key(), unsigned: :accept, timestamp: 0)

  @doc "The signing key of the visible vectors."
  def key, do: Base.decode16!("9d3487bc04d9cc324c57a07307e5d89594ac6b1b6813c161392253380de56baa", case: :lower)

  @doc "A decoded frame's fields as JSON values (floats, NaN strings, ...), for comparison with a record."
  def json_fields(frame) do
    {:ok, map} = frame |> Dolphin.MAVLink.Record.encode() |> IO.iodata_to_binary() |> Dolphin.MAVLink.JSON.decode()
    map["fields"]
  end

  @doc "Deep equality that tells -0.0 from 0.0 (Erlang's == and === do not)."
  def same?(a, b) when is_float(a) and is_float(b), do: <<a::float-64>> == <<b::float-64>>
  def same?(a, b) when is_list(a) and is_list(b), do: length(a) == length(b) and Enum.all?(Enum.zip(a, b), fn {x, y} -> same?(x, y) end)

  def same?(a, b) when is_map(a) and is_map(b),
    do: Map.keys(a) == Map.keys(b) and Enum.all?(a, fn {k, v} -> same?(v, Map.fetch!(b, k)) end)

  def same?(a, b), do: a === b
end
