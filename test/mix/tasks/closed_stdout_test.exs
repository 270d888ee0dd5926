defmodule Mix.Tasks.ClosedStdoutTest do
  # Tasks whose standard output is closed under them (`| head`), each in its
  # own VM as a shell runs them. Writes files only: async.
  use ExUnit.Case, async: true

  alias Dolphin.CLI.Stdout
  alias Dolphin.MAVLink.{Frame, Tlog}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Test.Shell

  @moduletag :tmp_dir
  @moduletag timeout: 600_000

  describe "the group leader of Dolphin.CLI.Stdout" do
    test "passes I/O on to the device, and ends the command when the device's pipe is closed" do
      {:ok, device} = StringIO.open("typed\n")
      Process.unlink(device)
      me = self()
      leader = Stdout.start(device, fn -> send(me, :closed) end)

      assert IO.write(leader, "written") == :ok
      assert IO.read(leader, :line) == "typed\n"
      assert StringIO.contents(device) == {"", "written"}

      # What :user does when standard output is a closed pipe: its port
      # meets the closed pipe, or it writes to its port gone for that reason.
      Process.exit(device, :epipe)
      assert_receive :closed, 30_000

      {:ok, device} = StringIO.open("")
      Process.unlink(device)
      Stdout.start(device, fn -> send(me, :closed) end)
      Process.exit(device, {:badarg, [{:erlang, :port_command, [:port, "x"], []}, {:user, :put_chars, 3, []}]})
      assert_receive :closed, 30_000
    end

    test "goes with a device that ends for another reason" do
      {:ok, device} = StringIO.open("")
      Process.unlink(device)
      leader = Stdout.start(device, fn -> flunk("not a closed pipe") end)
      ref = Process.monitor(leader)
      Process.exit(device, :shutdown)
      assert_receive {:DOWN, ^ref, :process, ^leader, :shutdown}, 30_000
    end
  end

  # A telemetry log far larger than a pipe holds: 40,000 heartbeats.
  defp big_tlog(dir) do
    path = Path.join(dir, "big.tlog")
    heartbeat = %M.Heartbeat{type: 2, autopilot: 3, base_mode: 0x81, custom_mode: 4, mavlink_version: 3}
    File.write!(path, for(i <- 0..39_999, do: Tlog.record(1_800_000_000_000_000 + i * 1000, Frame.encode(heartbeat, sysid: 1, compid: 1, seq: rem(i, 256)))))
    path
  end

  test "mix mavlink.decode | head -1: one line, nothing on stderr (no crash, no summary: the rest is not decoded), status 141", %{tmp_dir: dir} do
    result = Shell.run("mix mavlink.decode #{Shell.quote(big_tlog(dir))} --tlog | head -1")
    assert [line] = String.split(result.out, "\n", trim: true)
    assert line =~ ~s("msg":"HEARTBEAT")
    assert result.err == ""
    assert result.statuses == [141, 0]
  end

  test "mix mavlink.decode | mix mavlink.encode - | head -2: two frames, no error, encode ends with 141", %{tmp_dir: dir} do
    result = Shell.run("mix mavlink.decode #{Shell.quote(big_tlog(dir))} --tlog | mix mavlink.encode - | head -2")
    assert [_, _] = String.split(result.out, "\n", trim: true), inspect(result)
    [decode, encode, head] = result.statuses
    assert {encode, head} == {141, 0}, inspect(result)
    # decode may have written all before encode stopped reading: then it ended as usual, with its summary.
    case decode do
      141 -> assert result.err == ""
      0 -> assert "frames: 40000, " <> _ = result.err
    end

    assert length(String.split(result.err, "\n", trim: true)) <= 1
  end

  test "mix dolphin.run | head -1: the run ends at once, quietly, status 141", %{tmp_dir: dir} do
    script = Path.join(dir, "ticks.exs")
    File.write!(script, "use Dolphin.Script\nforever do\n  message(\"tick\")\n  pause(seconds(1))\nend\n")
    events = Path.join(dir, "events.jsonl")
    # An hour of clock time at 100x is 36 s of real time: it would print 3,600 ticks.
    result = Shell.run("mix dolphin.run #{Shell.quote(script)} --fake 1 --speedup 100 --for 1h --events #{Shell.quote(events)} | head -1")
    assert [_] = String.split(result.out, "\n", trim: true)
    assert result.err == ""
    assert result.statuses == [141, 0]
    # It did not go on: no script_finished, a few ticks at most.
    names = events |> File.read!() |> String.split("\n", trim: true) |> Enum.map(&(:jiffy.decode(&1, [:return_maps])["event"]))
    refute "script_finished" in names
    assert Enum.count(names, &(&1 == "message")) < 3_600
  end
end
