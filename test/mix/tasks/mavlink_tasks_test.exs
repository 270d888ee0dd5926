defmodule Mix.Tasks.MavlinkTasksTest do
  # Captures the standard error, the VM's one device, which compiling a
  # script (in the async tests that run examples) swaps too: not async.
  use ExUnit.Case, async: false

  import ExUnit.CaptureIO

  alias Dolphin.MAVLink.JSON
  alias Dolphin.Test.Vectors
  alias Mix.Tasks.Mavlink.{Decode, Encode}

  test "decode prints exactly the expected records of stream.bin, and a summary" do
    {:ok, input} = File.open(Vectors.path!("stream.bin"), [:read, :binary])
    {:ok, output} = StringIO.open("")
    stats = Decode.decode(input, output, signing: Vectors.signing())
    {_, out} = StringIO.contents(output)

    lines = String.split(out, "\n", trim: true)
    expected = for {_, _, rec} <- Vectors.records("stream.expected.jsonl"), do: rec
    assert length(lines) == length(expected)

    for {line, rec} <- Enum.zip(lines, expected) do
      {:ok, got} = JSON.decode(line)
      keys = ~w(msg id mavlink signed sysid compid seq fields)
      assert Map.take(got, keys) |> Vectors.same?(Map.take(rec, keys)), "record #{rec["index"]}"
      if rec["signed"], do: assert(Map.drop(got["signing"], ["secret_key"]) == Map.drop(rec["signing"], ["secret_key"]))
    end

    assert Decode.summary(stats) =~ "frames: #{length(expected)}, bytes: #{File.stat!(Vectors.path!("stream.bin")).size}"
  end

  test "encode turns records back into their frames, and reports bad lines by number" do
    lines = for {_, line, _} <- Vectors.records("ardupilotmega.signed.jsonl"), do: line
    frames = for {_, _, rec} <- Vectors.records("ardupilotmega.signed.jsonl"), do: rec["frame"]
    {:ok, output} = StringIO.open("")

    errors =
      capture_io(:stderr, fn ->
        send(self(), {:errors, Encode.encode(lines ++ ["", ~s({"msg":"NOPE","fields":{}}), ~s({"msg":"HEARTBEAT","fields":{"type":300}}), "{"], output)})
      end)

    assert_received {:errors, [{_, "unknown message \"NOPE\""}, {_, type_error}, {_, json_error}]}
    assert type_error =~ "cannot encode HEARTBEAT.type = 300"
    assert json_error =~ "not valid JSON"
    assert errors =~ "line #{length(lines) + 2}: unknown message"
    {_, out} = StringIO.contents(output)
    assert String.split(out, "\n", trim: true) == frames
  end

  test "records that cannot be encoded are errors, never crashes" do
    huge = String.duplicate("9", 400)

    lines = [
      ~s({"msg":"WHEEL_DISTANCE","fields":{"distance":[#{huge}]}}),
      ~s({"msg":"HEARTBEAT","signed":true,"signing":{"secret_key":5,"link_id":0,"timestamp":1},"fields":{}}),
      ~s({"msg":"HEARTBEAT","id":30,"fields":{}}),
      ~s({"msg":"GOPRO_SET_REQUEST","fields":{"value":["ab",3,4,5]}})
    ]

    {:ok, output} = StringIO.open("")
    capture_io(:stderr, fn -> send(self(), {:errors, Encode.encode(lines, output)}) end)
    assert_received {:errors, [{1, e1}, {2, e2}, {3, e3}, {4, e4}]}
    assert e1 =~ "WHEEL_DISTANCE.distance: not a number"
    assert e2 =~ "a signed record needs"
    assert e3 == ~s("msg" HEARTBEAT has id 0, not 30)
    assert e4 =~ ~s(element "ab")
    assert StringIO.contents(output) == {"", ""}
  end

  test "decode reads .tlog files and rejects bad usage" do
    assert_raise Mix.Error, ~r/usage: mix mavlink.decode/, fn -> Decode.run([]) end
    assert_raise Mix.Error, ~r/cannot read .*nope.bin/, fn -> Decode.run(["nope.bin"]) end
    assert_raise Mix.Error, ~r/--reject-unsigned needs --key/, fn -> Decode.run(["x", "--reject-unsigned"]) end
    assert_raise Mix.Error, ~r/--key must be 64 hex digits/, fn -> Decode.run(["x", "--key", "abc"]) end
    # 32 characters would be a raw 32-byte key to Signing.new/1; on the command line it is a mistake.
    assert_raise Mix.Error, ~r/--key must be 64 hex digits/, fn -> Decode.run(["x", "--key", String.duplicate("ab", 16)]) end
    assert_raise Mix.Error, ~r/unknown or malformed option --bogus/, fn -> Decode.run(["x", "--bogus"]) end
    assert_raise Mix.Error, ~r/usage: mix mavlink.encode/, fn -> Encode.run([]) end

    frame = Dolphin.MAVLink.Frame.encode(%Dolphin.MAVLink.Ardupilotmega.Heartbeat{type: 6}, sysid: 3)
    tlog = IO.iodata_to_binary([Dolphin.MAVLink.Tlog.record(1, frame), Dolphin.MAVLink.Tlog.record(2, frame)])
    {:ok, output} = StringIO.open("")
    # A file, not a StringIO: StringIO hands back characters, not bytes.
    path = Path.join(System.tmp_dir!(), "dolphin-#{System.unique_integer([:positive])}.tlog")
    File.write!(path, tlog)
    {:ok, io} = File.open(path, [:read, :binary])
    stats = Decode.decode(io, output, tlog: true)
    File.rm!(path)
    {_, out} = StringIO.contents(output)
    assert stats.frames == 2
    assert [%{"msg" => "HEARTBEAT", "sysid" => 3, "fields" => %{"type" => 6}} | _] = Enum.map(String.split(out, "\n", trim: true), &elem(JSON.decode(&1), 1))
  end
end
