defmodule Dolphin.Interop.UserDialectTest do
  # A dialect of the user's own (Dolphin.MAVLink.UserDialect, compiled in
  # tests from test/fixtures/mavlink/user/) on the wire as the reference
  # implementation has it: pymavlink's mavgen builds the same XML, and a
  # message of it encodes to the same bytes both ways (CRC_EXTRA included).
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.Frame
  alias Dolphin.MAVLink.UserDialect.SmokeSensor

  @moduletag :tmp_dir

  # A user's message whose id is one of ArduPilot's is refused, naming both.
  doctest Dolphin.MAVLink.Generator, only: [taken_id: 2]

  @xml Path.expand("../fixtures/mavlink/user/fire_sensors.xml", __DIR__)

  @script """
  import sys, os
  from pymavlink.generator import mavgen
  xml, out, ours = sys.argv[1], sys.argv[2], sys.argv[3]
  mavgen.mavgen(mavgen.Opts(output=os.path.join(out, "fire.py"), wire_protocol="2.0", language="Python3", validate=False), [xml])
  sys.path.insert(0, out)
  import fire
  mav = fire.MAVLink(None, srcSystem=3, srcComponent=191)
  print(fire.MAVLink_smoke_sensor_message(1, 12.5, 2150).pack(mav).hex())
  m = mav.decode(bytearray(bytes.fromhex(ours)))
  print(m.get_type(), m.sensor_id, m.ppm, m.temperature)
  """

  test "a user's message encodes as pymavlink's mavgen encodes it, and pymavlink reads ours", %{tmp_dir: dir} do
    ours = Frame.encode(%SmokeSensor{sensor_id: 1, ppm: 12.5, temperature: 2150}, sysid: 3, compid: 191, seq: 0)
    {out, 0} = System.cmd(Dolphin.Test.Pymavlink.python(), ["-c", @script, @xml, dir, Base.encode16(ours, case: :lower)], stderr_to_stdout: true)
    [theirs, read] = out |> String.split("\n", trim: true) |> Enum.take(-2)
    assert theirs == Base.encode16(ours, case: :lower)
    assert read == "SMOKE_SENSOR 1 12.5 2150"
    assert {:ok, %Frame{message: %SmokeSensor{ppm: 12.5, temperature: 2150}}, ""} = Frame.decode(Base.decode16!(theirs, case: :lower), Dolphin.MAVLink.default_dialect())
  end
end
