defmodule Dolphin.Test.Vectors do
  @moduledoc """
  MAVLink test vectors, read with the exact JSON reader. Two sets, in the same
  format:

    * `:own` — the project's, in `test/vectors/`, made with pymavlink by
      `scripts/make_vectors.py` (`scripts/bootstrap` runs it);
    * `:shared` — the shared vectors in `mavlink/vectors/` of the shared folder
      (`../shared` beside the project, or `$DOLPHIN_SHARED`), cross-checked
      with the MAVLink C library; optional: the tests that read them are
      tagged `:shared_vectors` and excluded when the folder is absent.
  """

  @own Path.expand("../vectors", __DIR__)
  @shared_default Path.expand("../../../shared", __DIR__)

  @doc "The shared folder: `$DOLPHIN_SHARED`, else `../shared` beside the project."
  def shared_root, do: System.get_env("DOLPHIN_SHARED", @shared_default)

  @doc "The directory of a set of vectors (`:own` or `:shared`)."
  def dir(:own), do: @own
  def dir(:shared), do: Path.join(shared_root(), "mavlink/vectors")

  @doc "Whether a set of vectors is there."
  def available?(set), do: File.dir?(dir(set))

  @doc "Path of a file of the project's vectors; see `path!/2`."
  def path!(name), do: path!(:own, name)

  @doc "Path of a vectors file; fails the test with a clear message when missing."
  def path!(set, name) do
    path = Path.join(dir(set), name)
    File.exists?(path) || raise "test vectors not found: #{path} (#{how_to_get(set)})"
    path
  end

  defp how_to_get(:own), do: "scripts/bootstrap makes them with scripts/make_vectors.py"
  defp how_to_get(:shared), do: "the shared folder is ../shared beside the project, or $DOLPHIN_SHARED"

  @doc "Records of a .jsonl file of the project's vectors; see `records/2`."
  def records(name), do: records(:own, name)

  @doc "Records of a .jsonl file of a set as `{line_number, raw_line, map}`."
  def records(set, name) do
    set
    |> path!(name)
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

  @doc "The signing key of both sets (SHA-256 of the ASCII string `mavlink-vectors/visible/signing-key`)."
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
