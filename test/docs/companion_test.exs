defmodule Dolphin.Docs.CompanionTest do
  # docs/language.md's companion computer ("Bringing a real sensor"), run
  # as written with pymavlink beside a vehicle of this test: its readings
  # reach the vehicle's view as a declared sensor's.
  use ExUnit.Case, async: true

  alias Dolphin.{Clock, Sensors, Vehicles}
  alias Dolphin.Test.{GroundStation, Pymavlink, ScriptedVehicle}

  @moduletag :tmp_dir

  test "the companion of docs/language.md sends SMOKE as NAMED_VALUE_FLOAT from component 191; the vehicle reads it", %{tmp_dir: dir} do
    doc = File.read!(Path.expand("../../docs/language.md", __DIR__))
    [_, code] = Regex.run(~r/<!-- companion -->\n```python\n(.*?)```/s, doc)
    companion = Path.join(dir, "companion.py")
    File.write!(companion, code)

    Dolphin.Test.Instance.start!()
    port = GroundStation.open()
    {:ok, _} = ScriptedVehicle.start_link(port: port, sysid: 41)
    Dolphin.Test.Wait.until(fn -> match?({:ok, %{type: :uav}}, Vehicles.view(41)) end)
    {:ok, smoke} = Sensors.new(:smoke, from: {:named_value, "SMOKE"})
    :ok = Vehicles.watch_sensors([smoke])
    Vehicles.subscribe(41)

    python = Port.open({:spawn_executable, Pymavlink.python()}, [:binary, :exit_status, :stderr_to_stdout, args: [companion, "udpout:127.0.0.1:#{port}", "41"]])
    {:os_pid, os_pid} = Port.info(python, :os_pid)

    on_exit(fn -> System.cmd("kill", ["#{os_pid}"], stderr_to_stdout: true) end)

    assert %{value: value, compid: 191} = await_reading(python, {:named_value, "SMOKE"})
    assert_in_delta value, 0.42, 1.0e-6
  end

  defp await_reading(python, source) do
    receive do
      {:dolphin, {:vehicle, 41}, {:view, view}} ->
        Map.get(view.sensors, source) || await_reading(python, source)

      {^python, {:exit_status, status}} ->
        flunk("the companion ended with status #{status}")

      {^python, {:data, output}} ->
        flunk("the companion said: #{output}")
    after
      Clock.to_real_ms(30_000) -> flunk("no SMOKE reading from the companion: #{inspect(Vehicles.view(41))}")
    end
  end
end
