defmodule Mix.Tasks.Dolphin.ParamTest do
  # `mix dolphin.param` in its own OS process, as a user runs it, against
  # scripted vehicles of this VM that keep parameters as ArduPilot does
  # (test/support/scripted_vehicle.ex), each sending to its own port.
  use ExUnit.Case, async: true

  alias Dolphin.Test.{GroundStation, MixCommand, ScriptedVehicle}

  @moduletag :tmp_dir
  @moduletag timeout: 300_000

  # A vehicle sending to a port of its own, and that port as --connect.
  defp vehicle(sysid) do
    port = GroundStation.free_udp_port()
    {:ok, pid} = ScriptedVehicle.start_link(port: port, sysid: sysid)
    {pid, "udpin:127.0.0.1:#{port}"}
  end

  test "get, set (read back), a refused value, an unknown name, list, save and load", %{tmp_dir: dir} do
    [{_, at_a}, {b, at_b}, {_, at_c}, {_, at_d}, {_, at_e}, {f, at_f}, {_, at_g}] = Enum.map(21..26, &vehicle/1) ++ [vehicle(28)]
    saved = Path.join(dir, "saved.parm")
    to_load = Path.join(dir, "load.parm")
    File.write!(to_load, "# two good, one out of range, one unknown\nP2_MAX 42\nP1_RATE,7\nP3_TRIM\t25.0\nNO_SUCH 1\n")

    assert [{0, get}, {0, set}, {1, refused}, {1, unknown}, {0, save}, {1, load}, {0, list}] =
             MixCommand.run_all([
               ~w(dolphin.param get P2_MAX --connect #{at_a}),
               ~w(dolphin.param set P2_MAX 42 --connect #{at_b}),
               ~w(dolphin.param set P3_TRIM 25 --connect #{at_c}),
               ~w(dolphin.param get P2_MAXX --connect #{at_d}),
               ~w(dolphin.param save #{saved} --connect #{at_e}),
               ~w(dolphin.param load #{to_load} --connect #{at_f} --vehicle 26),
               ~w(dolphin.param list P12_ --connect #{at_g})
             ])

    assert get =~ "vehicle 21: P2_MAX = -6"
    assert set =~ "vehicle 22: P2_MAX set to 42"
    assert ScriptedVehicle.params(b)["P2_MAX"] == 42
    assert refused =~ "mix dolphin.param: vehicle 23 kept P3_TRIM at 10 when asked for 25"
    assert unknown =~ ~r/mix dolphin.param: vehicle 24 has no parameter P2_MAXX \(did you mean P2_MAX/
    assert save =~ "vehicle 25: saved 300 parameters to #{saved}"
    lines = saved |> File.read!() |> String.split("\n", trim: true) |> tl()
    assert length(lines) == 300
    assert "P2_MAX -6" in lines and "P3_TRIM 0.375" in lines
    assert load =~ "set 2 of 4 parameters from #{to_load}; not set:"
    assert load =~ "vehicle 26 kept P3_TRIM at 10 when asked for 25"
    assert load =~ "vehicle 26 has no parameter NO_SUCH"
    assert ScriptedVehicle.params(f)["P1_RATE"] == 7
    # The whole list fetched, the names that contain the filter shown.
    assert list =~ ~r/^P12_GAIN  -?\d+(\.\d+)?$/m
    assert list =~ "vehicle 28: 1 of 300 parameters"
  end

  test "bad usage: no command, a value that is no number, a file to load that is not NAME VALUE", %{tmp_dir: dir} do
    bad = Path.join(dir, "bad.parm")
    File.write!(bad, "P1 1\nP2 two\n")
    {_, at} = vehicle(27)

    assert [{2, none}, {2, nan}, {1, file}] =
             MixCommand.run_all([
               ~w(dolphin.param --connect #{at}),
               ~w(dolphin.param set P1 fast --connect #{at}),
               ~w(dolphin.param load #{bad} --connect #{at})
             ])

    assert none =~ "mix dolphin.param: what to do: get, set, list, save or load"
    assert nan =~ "set P1 fast: the value is a number"
    assert file =~ ~s(#{bad}:2: "two" is not a number)
  end
end
