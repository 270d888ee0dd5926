defmodule Dolphin.MAVLink.VectorsTest do
  # Byte-exactness against the reference implementation's vectors (pymavlink):
  # the project's own (scripts/make_vectors.py; format in test/vectors/README.md)
  # and, when present, the shared ones.
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.{Ardupilotmega, Frame, Parser, Record, Signing}
  alias Dolphin.Test.Vectors

  @dialect Ardupilotmega

  # The project's own vectors always; the shared ones (cross-checked with the
  # MAVLink C library) when the shared folder is there: test_helper.exs
  # excludes the :shared_vectors tag otherwise.
  for set <- [:own, :shared] do
    describe "#{set} vectors" do
      if set == :shared, do: @describetag(:shared_vectors)
      @set set

      test "CRC_EXTRA and payload lengths of every message agree with the reference" do
        {:ok, table} = Dolphin.MAVLink.JSON.decode(File.read!(Vectors.path!(@set, "crc_extra.json")))
        assert map_size(table) == 301
        assert length(@dialect.messages()) == 301

        for {id, %{"name" => name, "crc_extra" => crc, "min_len" => min, "max_len" => max}} <- table do
          assert {module, ^crc, ^min, ^max} = @dialect.message_info(String.to_integer(id)), "#{name} (#{id})"
          assert module.__mavlink__(:name) == name
        end
      end

      for file <- ~w(ardupilotmega.v2.jsonl ardupilotmega.v1.jsonl ardupilotmega.signed.jsonl) do
        test "every record of #{file} decodes to its fields and encodes back to its frame" do
          for {n, line, rec} <- Vectors.records(@set, unquote(file)) do
            frame = Base.decode16!(rec["frame"], case: :lower)
            where = "#{unquote(file)}:#{n} #{rec["msg"]}"

            assert {:ok, decoded, <<>>} = Frame.decode(frame, @dialect), where
            assert decoded.message != nil, where
            assert {decoded.sysid, decoded.compid, decoded.seq, decoded.version} == {rec["sysid"], rec["compid"], rec["seq"], rec["mavlink"]}, where
            assert Vectors.same?(Vectors.json_fields(decoded), rec["fields"]), "#{where}: decoded #{inspect(Vectors.json_fields(decoded))}"

            if rec["signed"] do
              assert {:ok, _} = Signing.verify(Signing.new(key: Vectors.key(), timestamp: 0), decoded), where
            end

            assert {:ok, message, opts} = Record.decode(line, @dialect), where
            assert Base.encode16(Frame.encode(message, opts), case: :lower) == rec["frame"], where
          end
        end
      end

      test "a signed record fails verification with another key, and a replay is refused" do
        [{_, _, rec} | _] = Vectors.records(@set, "ardupilotmega.signed.jsonl")
        {:ok, frame, <<>>} = Frame.decode(Base.decode16!(rec["frame"], case: :lower), @dialect)

        assert {:error, :bad_signature, _} = Signing.verify(Signing.new(key: :binary.copy(<<1>>, 32)), frame)

        signing = Signing.new(key: Vectors.key(), timestamp: 0)
        assert {:ok, signing} = Signing.verify(signing, frame)
        assert {:error, :old_timestamp, _} = Signing.verify(signing, frame)
      end

      test "stream.bin yields exactly the expected frames, in order" do
        {bytes, expected} = stream(@set)
        {frames, parser} = Parser.feed(Parser.new(signing: Vectors.signing()), bytes)
        {rest, parser} = Parser.finish(parser)
        frames = frames ++ rest
        stats = Parser.stats(parser)

        decoded = Enum.filter(frames, & &1.message)
        assert length(expected) >= 1000
        assert length(decoded) == length(expected)
        assert stats.frames == length(expected)
        assert_same_frames(decoded, expected)
        # Everything that is not an expected frame was dropped and counted.
        expected_bytes = expected |> Enum.map(&(byte_size(&1["frame"]) |> div(2))) |> Enum.sum()
        unknown_bytes = frames |> Enum.reject(& &1.message) |> Enum.map(&byte_size(&1.raw)) |> Enum.sum()
        assert stats.bytes_skipped == byte_size(bytes) - expected_bytes - unknown_bytes
        assert stats.bad_crc > 0 and stats.bad_incompat_flags > 0 and stats.truncated == 1
      end

      test "stream.bin: chunking changes nothing: random split points, 1-byte feeds" do
        {bytes, expected} = stream(@set)

        for seed <- 1..3 do
          :rand.seed(:exsss, {seed, seed, seed})
          chunks = random_chunks(bytes, [])

          {frames, parser} =
            Enum.reduce(chunks, {[], Parser.new(signing: Vectors.signing())}, fn chunk, {acc, p} ->
              {frames, p} = Parser.feed(p, chunk)
              {acc ++ frames, p}
            end)

          {rest, parser} = Parser.finish(parser)
          assert_same_frames(Enum.filter(frames ++ rest, & &1.message), expected)
          assert Parser.stats(parser).frames == length(expected)
        end

        {frames, _} =
          bytes
          |> binary_part(0, 20_000)
          |> :binary.bin_to_list()
          |> Enum.reduce({[], Parser.new(signing: Vectors.signing())}, fn byte, {acc, p} ->
            {frames, p} = Parser.feed(p, <<byte>>)
            {Enum.reverse(frames) ++ acc, p}
          end)

        {whole, _} = Parser.feed(Parser.new(signing: Vectors.signing()), binary_part(bytes, 0, 20_000))
        assert Enum.map(Enum.reverse(frames), & &1.raw) == Enum.map(whole, & &1.raw)
      end
    end
  end

  defp stream(set) do
    bytes = File.read!(Vectors.path!(set, "stream.bin"))
    expected = for {_, _, rec} <- Vectors.records(set, "stream.expected.jsonl"), do: rec
    {bytes, expected}
  end

  defp assert_same_frames(frames, expected) do
    assert length(frames) == length(expected)

    for {frame, rec} <- Enum.zip(frames, expected) do
      where = "expected ##{rec["index"]} at offset #{rec["offset"]} (#{rec["msg"]})"
      assert Base.encode16(frame.raw, case: :lower) == rec["frame"], where
      assert Vectors.same?(Vectors.json_fields(frame), rec["fields"]), where
    end
  end

  defp random_chunks(<<>>, acc), do: Enum.reverse(acc)

  defp random_chunks(bytes, acc) do
    n = min(:rand.uniform(300), byte_size(bytes))
    <<chunk::binary-size(n), rest::binary>> = bytes
    random_chunks(rest, [chunk | acc])
  end
end
