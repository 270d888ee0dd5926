defmodule Dolphin.CLI.ValuesTest do
  use ExUnit.Case, async: true

  alias Dolphin.CLI.Values

  doctest Values

  @moduletag :tmp_dir

  defp message(opts, spec) do
    assert {:error, %Dolphin.CommandLineError{reason: :usage, message: message}} = Values.check(opts, spec)
    message
  end

  test "every kind reads its values and names the flag, the value and what is allowed when it will not do" do
    assert {:ok, [count: 254, first_sysid: 1, speedup: 0.01, seed: -3, web: 0]} =
             Values.check([count: "254", first_sysid: "1", speedup: ".01", seed: "-3", web: "0"], count: :vehicles, first_sysid: :sysid, speedup: :speedup, seed: :integer, web: :port)

    assert message([sim: "255"], sim: :vehicles) == "--sim 255: a number of vehicles from 1 to 254 (each needs a system id of its own)"
    assert message([first_sysid: "0"], first_sysid: :sysid) == "--first-sysid 0: a system id from 1 to 254 (255 is the ground station's)"
    assert message([speedup: "1001"], speedup: :speedup) =~ "--speedup 1001: a number from 0.01 to 1000"
    assert message([speedup: "fast"], speedup: :speedup) =~ "--speedup fast: a number from 0.01 to 1000"
    assert message([wait: "0"], wait: :wait) == "--wait 0: a number of seconds, more than 0 and at most 4294967 (49.7 days, the longest a timer holds)"
    assert message([wait: "5e6"], wait: :wait) =~ "--wait 5e6: a number of seconds, more than 0 and at most 4294967"
    assert message([for: "0"], for: :duration) == "--for 0: a duration more than 0 such as 90s, 10m, 1h or 500ms (a bare number is seconds)"
    assert message([for: "0.1ms"], for: :duration) =~ "--for 0.1ms: a duration more than 0"
    assert message([max_height: "-5"], max_height: :metres) == "--max-height -5: a number of metres, more than 0"
    assert message([cruise_speed: "nan"], cruise_speed: :speed) == "--cruise-speed nan: a speed in metres per second, more than 0"
    assert message([web: "65536"], web: :port) == "--web 65536: a TCP port from 1 to 65535 (0: any free one)"
    assert message([name: " "], name: :name) == ~s(--name " ": a name that is not empty)
    assert message([mode: "fly"], mode: {:one_of, %{"rtl" => :rtl, "land" => :land}}) == "--mode fly: land or rtl"
  end

  test "a location: the form, then each coordinate's range, as typed" do
    assert {:ok, [home: %{lat: -33.9, lon: 18.4, alt: 0.0}]} = Values.check([home: "-33.9, 18.4, 0"], home: :location)
    assert message([home: "north"], home: :location) == "--home north: LAT,LON,ALT: degrees, degrees, metres above mean sea level, e.g. 40.444233,-7.375234,820"
    assert message([home: "1,2"], home: :location) =~ "--home 1,2: LAT,LON,ALT"
    assert message([home: "-90.5,0,0"], home: :location) =~ "--home -90.5,0,0: the latitude -90.5 is not within -90..90"
    assert message([home: "0,180.01,0"], home: :location) =~ "--home 0,180.01,0: the longitude 180.01 is not within -180..180"
    assert message([home: "0,0,10001"], home: :location) =~ "--home 0,0,10001: the altitude 10001 m is not within -1000..10000"
  end

  test "endpoints: the kind asked for, a port 1..65535, a host" do
    assert {:ok, [connect: "udpin:0.0.0.0:14550", connect: "tcp:127.0.0.1:5760"]} =
             Values.check([connect: "udpin:0.0.0.0:14550", connect: "tcp:127.0.0.1:5760"], connect: {:keep, :endpoint})

    assert message([forward: "tcp:127.0.0.1:5760"], forward: {:keep, {:endpoint, [:udpout]}}) == "--forward tcp:127.0.0.1:5760: udpout:HOST:PORT here, not tcp"
    assert message([connect: "udpin:0.0.0.0:0"], connect: :endpoint) == "--connect udpin:0.0.0.0:0: the port is 1..65535"
    assert message([connect: "udpin:0.0.0.0:x"], connect: :endpoint) == "--connect udpin:0.0.0.0:x: the port x is not within 1..65535"
    assert message([connect: "serial:/dev/tty:1"], connect: :endpoint) == "--connect serial:/dev/tty:1: unknown kind serial: udpin:HOST:PORT or udpout:HOST:PORT or tcp:HOST:PORT"
    assert message([connect: "14550"], connect: :endpoint) == "--connect 14550: udpin:HOST:PORT or udpout:HOST:PORT or tcp:HOST:PORT, e.g. udpin:0.0.0.0:14550"
  end

  test "files: a directory is said to be one", %{tmp_dir: dir} do
    assert message([report: dir], report: :output) == "--report #{dir}: it is a directory, not a file"
    assert {:ok, [report: "r.html"]} = Values.check([report: "r.html"], report: :output)
    file = Path.join(dir, "s.exs")
    File.write!(file, "")
    assert Values.input_file(file, "script") == :ok
    assert {:error, e} = Values.input_file(dir, "script")
    assert e.message == "#{dir} is a directory, not a script"
    assert {:error, e} = Values.input_file(Path.join(dir, "none.exs"), "script")
    assert e.message == "no such script: #{Path.join(dir, "none.exs")}"
  end

  describe "the tasks' options" do
    test "mix dolphin.station" do
      station = &Mix.Tasks.Dolphin.Station.parse/1
      assert {:ok, opts} = station.(~w(--sname gs --sim 4 --first-sysid 251 --speedup 10))
      assert opts[:sim] == 4 and opts[:first_sysid] == 251 and opts[:speedup] == 10.0
      assert {:error, e} = station.(~w(--sname gs --sim 5 --first-sysid 251))
      assert e.message == "--sim 5 with --first-sysid 251: system ids 251..255 do not fit in 1..254 (255 is the ground station's)"
      assert {:error, e} = station.(~w(--sname gs --sim 1 --first-sysid 255))
      assert e.message =~ "--first-sysid 255: a system id from 1 to 254"
      assert {:error, e} = station.(~w(--sname gs --speedup 5000))
      assert e.message =~ "--speedup 5000: a number from 0.01 to 1000"
      assert {:error, e} = station.(~w(--sname gs --connect udpout:127.0.0.1:0))
      assert e.message == "--connect udpout:127.0.0.1:0: the port is 1..65535"
    end

    test "mix dolphin.check", %{tmp_dir: dir} do
      script = Path.join(dir, "s.exs")
      File.write!(script, "use Dolphin.Script\n")
      check = &Mix.Tasks.Dolphin.Check.parse/1
      assert {:error, e} = check.([script, "--sim", "0"])
      assert e.message =~ "--sim 0: a number of vehicles from 1 to 16256"
      assert {:error, e} = check.([script, "--connect", "udpin:127.0.0.1:14550", "--wait", "0"])
      assert e.message =~ "--wait 0: a number of seconds, more than 0"
      assert {:error, e} = check.([script, "--wait", "3"])
      assert e.message == "--wait goes with --connect"
      assert {:error, e} = check.([script, "--max-distance", "0"])
      assert e.message == "--max-distance 0: a number of metres, more than 0"
      assert {:error, e} = check.([dir])
      assert e.message == "#{dir} is a directory, not a script"
      assert {:error, e} = check.([script, "--fleet", dir])
      assert e.message == "#{dir} is a directory, not a fleet file"
    end

    test "mix dolphin.run", %{tmp_dir: dir} do
      script = Path.join(dir, "s.exs")
      File.write!(script, "use Dolphin.Script\n")
      run = &Mix.Tasks.Dolphin.Run.parse/1
      assert {:ok, _, opts} = run.([script, "--fake", "254", "--for", "1h", "--speedup", "1000"])
      assert opts[:fake] == 254 and opts[:for_ms] == 3_600_000 and opts[:for] == "1h"
      assert {:error, e} = run.([script, "--fake", "255"])
      assert e.message =~ "--fake 255: a number of vehicles from 1 to 254"
      assert {:error, e} = run.([script, "--for", "0"])
      assert e.message =~ "--for 0: a duration more than 0"
      assert {:error, e} = run.([script, "--for", "2000h"])
      assert e.message == "--for 2000h: at most 1193 h at speed-up 1 (49.7 days of real time, the longest a timer holds)"
      assert {:ok, _, _} = run.([script, "--for", "2000h", "--speedup", "2"])
      assert {:error, e} = run.([script, "--forward", "udpin:0.0.0.0:14551"])
      assert e.message == "--forward udpin:0.0.0.0:14551: udpout:HOST:PORT here, not udpin"
      assert {:error, e} = run.([script, "--events", dir])
      assert e.message == "--events #{dir}: it is a directory, not a file"
      assert {:error, e} = run.([script, "--sitl", "1", "--sitl-bin", dir])
      assert e.message == "--sitl-bin #{dir}: a directory, not a SITL binary"
      assert {:error, e} = run.([script, "--sitl", "1", "--sitl-defaults", dir])
      assert e.message == "--sitl-defaults #{dir}: a directory, not a parameter file"
      assert {:error, e} = run.([dir, "--fake", "1"])
      assert e.message == "#{dir} is a directory, not a script"
    end
  end
end
