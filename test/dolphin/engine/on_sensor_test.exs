defmodule Dolphin.Engine.OnSensorTest do
  # What an on_sensor task takes for a detection, of the readings the
  # vehicles keep: the examples fly it (test/examples/fire_watch_test.exs).
  use ExUnit.Case, async: true

  alias Dolphin.Engine.OnSensor
  alias Dolphin.Sensors.{Detection, Sensor}

  @smoke %Sensor{name: :smoke, source: {:named_value, "SMOKE"}}
  @fire Dolphin.Geo.location(40.4470, -7.3740)

  defp task, do: %OnSensor{sensor: @smoke, above: 0.4, apart: 150.0}

  # A view that kept these readings ({at, value, metres north of the fire}), newest first.
  defp view(id, readings) do
    history = for {at, value, north} <- readings, do: {at, value, Dolphin.Geo.offset(@fire, north, 0)}
    {at, value, position} = hd(history)
    %{id: id, sensors: %{@smoke.source => %{value: value, at: at, compid: 191, position: position, history: history, stale: []}}}
  end

  test "the reading that passed the threshold is found after the vehicle has flown out of the smoke" do
    # 0.7 at the fire, then 0.1 and 0.05 as it flew on: the latest is below.
    kept = Detection.kept(view(1, [{3_000, 0.05, 60}, {2_000, 0.1, 30}, {1_000, 0.7, 0}]), @smoke)
    assert [%Detection{value: 0.05}, %Detection{value: 0.1}, %Detection{value: 0.7, at_ms: 1_000, vehicle: 1} = at_fire] = kept
    assert OnSensor.strongest(kept, task(), []) == at_fire
    assert Dolphin.Geo.distance(at_fire.position, @fire) < 1
  end

  test "the highest of every vehicle's readings, away from the detections made" do
    one = Detection.kept(view(1, [{2_000, 0.9, 0}, {1_000, 0.5, 10}]), @smoke)
    two = Detection.kept(view(2, [{2_000, 0.6, 1_000}]), @smoke)
    assert %Detection{vehicle: 1, value: 0.9} = OnSensor.strongest(one ++ two, task(), [])
    # The fire was detected: what is near it is not a detection, the other place is.
    assert %Detection{vehicle: 2, value: 0.6} = OnSensor.strongest(one ++ two, task(), [@fire])
    assert OnSensor.strongest(one, task(), [@fire, nil]) == nil
    # None above the threshold, or no position: none.
    assert OnSensor.strongest(Detection.kept(view(1, [{1_000, 0.4, 0}]), @smoke), task(), []) == nil
    assert OnSensor.strongest([%Detection{vehicle: 1, sensor: :smoke, value: 0.9, position: nil}], task(), []) == nil
    assert Detection.kept(%{id: 1, sensors: %{}}, @smoke) == []
  end

  test "the vehicle sent is the free one nearest the detection, not the one that read it" do
    # 1 read the smoke and is looking at an earlier fire: not free, not offered.
    far = {2, Dolphin.Geo.offset(@fire, 400, 0)}
    near = {3, Dolphin.Geo.offset(@fire, -120, 50)}
    assert OnSensor.closest([far, near], @fire) == 3
    assert OnSensor.closest([near, far], @fire) == 3
    # A vehicle whose position is not known is not taken for near; with none known, the first.
    assert OnSensor.closest([{4, nil}, far], @fire) == 2
    assert OnSensor.closest([{4, nil}, {5, nil}], @fire) == 4
  end
end
