defmodule Dolphin.Test.Pymavlink do
  @moduledoc """
  The reference implementation (pymavlink, in the project's venv) from tests.
  """

  import ExUnit.Assertions

  @python Path.expand("../../.venv/bin/python", __DIR__)

  @doc "The venv's python; fails the test with what to do when it is missing."
  def python do
    assert File.exists?(@python), "#{@python} is missing: run scripts/bootstrap (make test does)"
    @python
  end

  @doc """
  Reads a .tlog with pymavlink's `mavutil`: `{sysid, message name, timestamp in
  seconds, message fields}` for each message, in order.
  """
  def read_tlog(path) do
    script = """
    import sys, json
    from pymavlink import mavutil
    m = mavutil.mavlink_connection(sys.argv[1], dialect="ardupilotmega")
    while True:
        msg = m.recv_match(blocking=False)
        if msg is None:
            break
        print(json.dumps([msg.get_srcSystem(), msg.get_type(), msg._timestamp, {k: v for k, v in msg.to_dict().items() if isinstance(v, (int, float, str))}]))
    """

    {out, 0} = System.cmd(python(), ["-c", script, path])

    for line <- String.split(out, "\n", trim: true) do
      {:ok, [sysid, type, ts, fields]} = Dolphin.MAVLink.JSON.decode(line)
      {sysid, type, ts, fields}
    end
  end
end
