defmodule Mix.Tasks.FlagValuesTest do
  # The mix tasks as a user runs them from the shell, each command in its
  # own OS process (a fresh VM, MIX_ENV=test): values out of range, files
  # that are directories, plans and scripts that are wrong. Nothing here
  # touches this VM's state: async.
  use ExUnit.Case, async: true

  @moduletag :tmp_dir
  @moduletag timeout: 600_000

  test "mix dolphin.sim: a value out of range is bad usage (status 2) naming the flag, the value and what is allowed" do
    # Port 9 (discard) on 127.0.0.1: were a vehicle started, it would send there.
    gcs = "--gcs=udpout:127.0.0.1:9"

    results =
      run_all([
        ~w(dolphin.sim --home 250,400,0 --for 5 --quiet) ++ [gcs],
        ~w(dolphin.sim --home 200,0,0 --for 5 --quiet) ++ [gcs],
        ~w(dolphin.sim --speedup 1e9 --for 1 --quiet) ++ [gcs],
        ~w(dolphin.sim --for 0 --quiet) ++ [gcs],
        ~w(dolphin.sim --count 0 --for 1 --quiet) ++ [gcs]
      ])

    assert [
             {2, home},
             {2, latitude},
             {2, speedup},
             {2, for_zero},
             {2, count}
           ] = results

    assert home =~ "mix dolphin.sim: --home 250,400,0: the latitude 250 is not within -90..90 (LAT,LON,ALT: degrees, degrees, metres above mean sea level)"
    refute home =~ "cannot encode"
    assert latitude =~ "--home 200,0,0: the latitude 200 is not within -90..90"
    assert speedup =~ "--speedup 1e9: a number from 0.01 to 1000 (beyond 1000 the simulated vehicles cannot keep up with the clock)"
    assert for_zero =~ "--for 0: a number of seconds, more than 0"
    assert count =~ "--count 0: a number of vehicles from 1 to 16256 (254 a network, each with a system id of its own there)"
    for {_, output} <- results, do: refute(output =~ ~r/bad :\w+|simulating/)
  end

  test "mix dolphin.run and dolphin.check: a directory is not a script, and values out of range are bad usage", %{tmp_dir: dir} do
    script = Path.join(dir, "hello.exs")
    File.write!(script, "use Dolphin.Script\nmessage \"hello\"\n")

    assert [{2, run_dir}, {2, for_zero}, {2, fake}, {2, check_dir}, {2, wait}] =
             run_all([
               ["dolphin.run", dir, "--fake", "1"],
               ["dolphin.run", script, "--fake", "1", "--for", "0"],
               ["dolphin.run", script, "--fake", "300"],
               ["dolphin.check", dir],
               ["dolphin.check", script, "--connect", "udpin:127.0.0.1:14999", "--wait", "0"]
             ])

    assert run_dir =~ "mix dolphin.run: #{dir} is a directory, not a script"
    refute run_dir =~ "no such script"
    assert for_zero =~ "mix dolphin.run: --for 0: a duration more than 0 such as 90s, 10m, 1h or 500ms"
    assert fake =~ "mix dolphin.run: --fake 300: a number of vehicles from 1 to 254"
    assert check_dir =~ "mix dolphin.check: #{dir} is a directory, not a script"
    assert wait =~ "mix dolphin.check: --wait 0: a number of seconds, more than 0"
  end

  test "mix dolphin.station and dolphin.console: values out of range are bad usage" do
    assert [{2, station}, {2, console}, {2, forward}] =
             run_all([
               ~w(dolphin.station --sname gsvalues --sim 1 --first-sysid 255),
               ~w(dolphin.console --sim 0),
               ~w(dolphin.console --forward tcp:127.0.0.1:5760)
             ])

    assert station =~ "mix dolphin.station: --first-sysid 255: a system id from 1 to 254 (255 is the ground station's)"
    assert console =~ "mix dolphin.console: --sim 0: a number of vehicles from 1 to 16256"
    assert forward =~ "mix dolphin.console: --forward tcp:127.0.0.1:5760: udpout:HOST:PORT here, not tcp"
  end

  test "mix dolphin.plan: a bad --home or --vehicle is bad usage; a plan that is wrong is said in its terms", %{tmp_dir: dir} do
    truncated = Path.join(dir, "truncated.plan")
    File.write!(truncated, ~s|{\n  "fileType": "Plan",\n  "version": 1,\n|)
    array = Path.join(dir, "array.plan")
    File.write!(array, "[]\n")
    example = Path.expand("../../../examples/single_vehicle.exs", __DIR__)

    # A directory named for a file to read is bad usage, as a missing file is.
    assert [{2, home}, {1, json}, {1, empty}, {2, directory}, {2, missions}, {2, vehicle}] =
             run_all([
               ["dolphin.plan", "export", example, "Survey Area", Path.join(dir, "o.plan"), "--home", "91,0,0"],
               ["dolphin.plan", "import", truncated],
               ["dolphin.plan", "import", array],
               ["dolphin.plan", "import", dir],
               ["dolphin.plan", "list", dir],
               ["dolphin.plan", "upload", truncated, "--connect", "udpin:127.0.0.1:14550", "--vehicle", "1@"]
             ])

    assert home =~ "mix dolphin.plan: --home 91,0,0: the latitude 91 is not within -90..90"
    end_byte = byte_size(File.read!(truncated)) + 1
    assert json =~ "#{truncated}: the plan is not valid JSON: line 4, column 1 (byte #{end_byte}): the text ends before the JSON value does"
    refute json =~ "truncated_json"
    assert empty =~ ~s|#{array}: not a QGroundControl plan: the file holds an array ([]), not an object with "fileType": "Plan"|
    assert directory =~ "mix dolphin.plan: #{dir} is a directory, not a plan file"
    assert missions =~ "#{dir}: cannot read: it is a directory, not a script or a file of missions"
    # A vehicle is a system id, or a name SYSID@NETWORK as vehicles() lists it.
    assert vehicle =~ "mix dolphin.plan: --vehicle 1@: a system id from 1 to 254, or SYSID@NETWORK as vehicles() lists it"
  end

  test "mix dolphin.check: the compiler's warnings in the script's terms, in a fresh VM", %{tmp_dir: dir} do
    types = Path.join(dir, "types.exs")
    File.write!(types, "use Dolphin.Script\nx = 1\nmessage \"\#{x.speed}\"\n")
    block = Path.join(dir, "block.exs")
    File.write!(block, "use Dolphin.Script\nv = pick()\nm = mission \"m\" do\n  takeoff 10\n  spiral(1, 2)\nend\nexecute %{v => m}\n")

    assert [{1, types_out}, {1, block_out}] = run_all([["dolphin.check", types, "--sim", "1"], ["dolphin.check", block, "--sim", "1"]])

    # The compiler names the file relative to the working directory, as the check's lines do.
    assert types_out =~ "#{Path.relative_to_cwd(types)}:3: warning: incompatible types:\n"
    assert block_out =~ "#{Path.relative_to_cwd(block)}:5: warning: undefined function spiral/2: no word of the language or of Elixir has that name"

    for output <- [types_out, block_out] do
      refute output =~ "Conflict found at"
      refute output =~ "Dolphin.Script.Compiled"
      refute output =~ "__script__"
    end
  end

  test "mix dolphin.run: a simulated sensor no model has, a world file that is wrong, a world without --sim", %{tmp_dir: dir} do
    script = Path.join(dir, "hello.exs")
    File.write!(script, "use Dolphin.Script\nmessage \"hello\"\n")
    world = Path.join(dir, "world.json")
    File.write!(world, ~s({\n  "fires": [\n    {"lat": 40.44, "lon": -7.37, "radius_m": 40,\n     "intensty": 0.9}\n  ]\n}\n))
    far = Path.join(dir, "far.json")
    File.write!(far, ~s({"fires": [{"lat": 40.44, "lon": -7.37, "radius_m": 40, "intensity": 0.9}],\n "wind": {"from_deg": 90, "speed_ms": 400}}))
    broken = Path.join(dir, "broken.json")
    File.write!(broken, ~s({"fires": [\n  {"lat": 40.44,}\n]}))

    assert [{2, sensor}, {1, key}, {1, range}, {1, json}, {2, alone}] =
             run_all([
               ["dolphin.run", script, "--sim", "copter:2+smke", "--no-tlog"],
               ["dolphin.run", script, "--sim", "copter:1+smoke", "--world", world, "--no-tlog"],
               ["dolphin.run", script, "--sim", "1", "--world", far, "--no-tlog"],
               ["dolphin.run", script, "--sim", "1", "--world", broken, "--no-tlog"],
               ["dolphin.run", script, "--fake", "1", "--world", world]
             ])

    assert sensor =~ ~s(mix dolphin.run: --sim copter:2+smke: no simulated sensor "smke": the simulator's sensors are range, smoke, water_temp)
    assert key =~ ~s|#{world}: line 4: fires[0]: unknown key "intensty" (did you mean "intensity"?); a fire takes lat, lon, radius_m, intensity|
    assert range =~ ~s|#{far}: line 2: wind.speed_ms: 400 is out of range: the wind's speed_ms is 0..40|
    assert json =~ ~s|#{broken}: line 2, column 17 (byte 29): unexpected "}|
    assert alone =~ "mix dolphin.run: --world is what simulated sensors sense: it goes with --sim or --sitl"
    for {_, output} <- [key, range, json], do: refute(output =~ "hello")
  end

  defp run_all(commands), do: Dolphin.Test.MixCommand.run_all(commands, [{"ERL_EPMD_ADDRESS", "127.0.0.1"}])
end
