defmodule Dolphin.SITL.ErrorTest do
  # Starts a local link (an ephemeral port) and no real SITL: untagged.
  use ExUnit.Case, async: false

  alias Dolphin.SITL

  doctest Dolphin.SITL.Error

  test "a missing binary is an error naming where it was looked for" do
    assert {:error, %SITL.Error{reason: :binary_missing, path: "/nonexistent/arducopter", from: "--sitl-bin"} = e} =
             SITL.start(1, bin: "/nonexistent/arducopter")

    assert Exception.message(e) == "--sitl: no ArduCopter SITL binary at /nonexistent/arducopter (--sitl-bin)"
  end

  @tag :tmp_dir
  test "missing defaults, beside the binary or given", %{tmp_dir: dir} do
    fake = Path.join(dir, "arducopter")
    File.write!(fake, "#!/bin/sh\nexit 3\n")
    File.chmod!(fake, 0o755)
    assert {:error, %SITL.Error{reason: :no_defaults} = e} = SITL.start(1, bin: fake)
    assert Exception.message(e) =~ "--sitl: no copter.parm beside #{fake}: give the defaults file"
    assert {:error, %SITL.Error{reason: :defaults_missing} = e} = SITL.start(1, bin: fake, defaults: ["/nonexistent/x.parm"])
    assert Exception.message(e) == "--sitl: no such defaults file: /nonexistent/x.parm"
  end

  test "an instance's end is told with its last lines" do
    e = %SITL.Error{reason: :exited, vehicle: 2, detail: 3, output: ["bad option --model", "giving up"]}
    assert Exception.message(e) == "--sitl: the ArduCopter SITL of vehicle 2 exited with status 3 before it answered; its last lines:\n    bad option --model\n    giving up"
    e = %SITL.Error{reason: :never_answered, vehicle: [1, 2], port: 5000, detail: "arducopter -I0", output: []}
    assert Exception.message(e) == "--sitl: vehicle 1, 2 never answered on 127.0.0.1:5000 (ArduCopter SITL of vehicle 1: arducopter -I0); it printed nothing"
  end
end
