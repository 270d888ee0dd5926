defmodule Dolphin.SensorsTest do
  # Sensors as a script declares and reads them: the declaration's checks
  # at compile time, the readings folded into a vehicle's view from real
  # frames of a simulated vehicle's companion computer, and their
  # staleness. Each test in an instance of its own: async.
  use ExUnit.Case, async: true

  alias Dolphin.{Clock, Script, Sensors, Vehicles}
  alias Dolphin.Engine.Snapshot
  alias Dolphin.Script.Error
  alias Dolphin.Sensors.Readings
  alias Dolphin.Sim.World
  alias Dolphin.Test.{GroundStation, Wait}

  doctest Dolphin.Sensors
  doctest Dolphin.Sensors.Readings
  doctest Dolphin.Sensors.Detection

  @smoke_source {:named_value, "SMOKE"}

  defp compile(source) do
    case Script.compile_string(source, "sensors.exs") do
      {:ok, script} ->
        Script.purge(script)
        :ok

      {:error, %Error{} = e} ->
        {e.line, e.message}
    end
  end

  describe "declaring and reading, checked when the script is compiled" do
    test "a declared sensor reads in conditions and statements; every reader compiles" do
      assert :ok =
               compile("""
               use Dolphin.Script
               sensor :smoke, from: {:named_value, "SMOKE"}, stale_after: seconds(5), keep: minutes(2)
               sensor :water_temp, from: {:message, :SCALED_PRESSURE2, :temperature}, scale: 0.01, unit: :celsius
               v = pick(sensors: [:smoke, :water_temp])
               execute wait_for(sensor(v, :smoke) > 0.4 and peak(v, :smoke, within: seconds(30)) > 0.5)
               message(inspect({sensor(v, :water_temp), sensor_age(v, :smoke), peak_position(v, :smoke, within: minutes(1))}))
               """)
    end

    test "a typo in a sensor's name is an error at its line, with the name that is near" do
      assert {4, message} =
               compile("""
               use Dolphin.Script
               sensor :smoke, from: {:named_value, "SMOKE"}
               v = pick()
               execute wait_for(sensor(v, :smok) > 0.4)
               """)

      assert message =~ "unknown sensor :smok; did you mean :smoke?; declared: :smoke"
    end

    test "a sensor read before any is declared says how to declare one" do
      assert {2, message} = compile("use Dolphin.Script\nmessage(inspect(sensor(1, :smoke)))\n")
      assert message =~ ~s|no sensor is declared above this line (sensor :smoke, from: {:named_value, "NAME"})|
    end

    test "a message or field the dialect does not have, or a field that is no number, is an error at the declaration's line" do
      for {from, said} <- [
            {"{:message, :SCALED_PRESURE2, :temperature}", "no message SCALED_PRESURE2 in the dialect; did you mean SCALED_PRESSURE2"},
            {"{:message, :SCALED_PRESSURE2, :temperatur}", "SCALED_PRESSURE2 has no field :temperatur; did you mean :temperature"},
            {"{:message, :STATUSTEXT, :text}", "STATUSTEXT.text is not a number (char[50]): a sensor reads one numeric field"},
            {~s({:named_value, "MUCH_TOO_LONG"}), "a named value's name has 1 to 10 characters"},
            {"{:named, \"SMOKE\"}", "from: takes {:named_value, \"NAME\"} or {:message, :MESSAGE_NAME, :field}"}
          ] do
        assert {3, message} = compile("use Dolphin.Script\n_ = 1\nsensor :s, from: #{from}\n"), from
        assert message =~ said
      end

      assert {2, message} = compile("use Dolphin.Script\nsensor :s, from: {:named_value, \"S\"}, stale: 5\n")
      assert message =~ "unknown option :stale; did you mean :scale, :stale_after?"
    end

    test "a peak over longer than the sensor keeps is refused, naming the keep: that would do" do
      assert {3, message} =
               compile("""
               use Dolphin.Script
               sensor :smoke, from: {:named_value, "SMOKE"}
               execute wait_for(peak(1, :smoke, within: minutes(2)) > 0.4)
               """)

      assert message =~ "sensor :smoke keeps 60000 ms of readings; declare it with keep: 120000 or more"
    end

    test "a sensor declared twice differently, or with options that need the script's variables, is refused" do
      assert {3, message} = compile("use Dolphin.Script\nsensor :s, from: {:named_value, \"S\"}\nsensor :s, from: {:named_value, \"T\"}\n")
      assert message =~ "sensor :s is declared twice, differently"

      assert {3, message} = compile("use Dolphin.Script\nname = \"S\"\nsensor :s, from: {:named_value, name}\n")
      assert message =~ "its options are fixed values"
    end
  end

  describe "readings" do
    test "a source declared twice keeps the longest history and each staleness limit" do
      {:ok, a} = Sensors.new(:a, from: {:named_value, "X"}, stale_after: 2_000, keep: 10_000)
      {:ok, b} = Sensors.new(:b, from: {:named_value, "X"}, stale_after: 5_000)
      assert %{{:named_value, "X"} => %{keep: 60_000, stale_after: [2_000, 5_000]}} = Readings.declare(%{}, [a, b])
    end

    test "a reading is stale only while it is the latest; a newer one is fresh again" do
      watch = Readings.watch(%{@smoke_source => %{keep: 60_000, stale_after: [1_000]}})
      msg = %Dolphin.MAVLink.Ardupilotmega.NamedValueFloat{name: "SMOKE", value: 0.3}
      r = Readings.fold(%{}, watch, 191, msg, 1_000, nil)
      assert [{@smoke_source, 1_000}] = Readings.fresh(%{}, r)
      stale = Readings.stale(r, @smoke_source, 1_000, 1_000)
      assert stale[@smoke_source].stale == [1_000]
      assert :unchanged = Readings.stale(stale, @smoke_source, 1_000, 1_000)
      newer = Readings.fold(stale, watch, 191, %{msg | value: 0.4}, 1_500, nil)
      assert newer[@smoke_source].stale == []
      assert :unchanged = Readings.stale(newer, @smoke_source, 1_000, 1_000)
      # NaN (the codec's :nan) is no reading.
      assert Readings.fold(newer, watch, 191, %{msg | value: :nan}, 1_600, nil) == newer
    end
  end

  describe "the world file" do
    test "the world of docs/simulator.md and the examples' worlds are worlds" do
      doc = File.read!(Path.expand("../../docs/simulator.md", __DIR__))
      [_, json] = Regex.run(~r/<!-- world -->\n```json\n(.*?)```/s, doc)
      assert {:ok, %World{fires: [_], obstacles: [_], water: %{fields: [_]}, sensing: %{rate_hz: 4.0, noise: 0.02}}} = World.parse(json)

      for path <- Path.wildcard(Path.expand("../../examples/worlds/*.json", __DIR__)),
          do: assert({:ok, %World{}} = World.read(path), path)
    end

    test "a world that is wrong is refused with the key's path and its line: out of range, not a number, missing, not a list" do
      refused = fn text -> assert({:error, why} = World.parse(text), text) && why end

      assert refused.(~s({"fires": [\n  {"lat": 40.4, "lon": -7.3, "radius_m": 40,\n   "intensity": 1.5}\n]})) ==
               "line 3: fires[0].intensity: 1.5 is out of range: a fire's intensity is 0..1"

      assert refused.(~s({"fires": [{"lat": 91, "lon": -7.3, "radius_m": 40, "intensity": 0.5}]})) ==
               "line 1: fires[0].lat: 91 is out of range: a fire's lat is -90..90"

      assert refused.(~s({"obstacles": [\n {"lat": 40.4, "lon": -7.3, "radius_m": "8", "height_m": 25}]})) ==
               "line 2: obstacles[0].radius_m: must be a number 0.1..1000, got a string"

      assert refused.(~s({"water": {"fields": [\n {"lat": 40.4, "lon": -7.3, "celsius": 19}]}})) ==
               "line 2: water.fields[0]: radius_m is missing; a water field takes lat, lon, radius_m, celsius"

      assert refused.(~s({"fires": {"lat": 40.4}})) == "line 1: fires: must be a list, got an object"
      assert refused.(~s({"sensors": {"rate_hz": 100}})) == "line 1: sensors.rate_hz: 100 is out of range: a simulated sensor's rate_hz is 0.1..50"
      assert refused.(~s({"sensors": {"rate": 5}})) =~ ~s[line 1: sensors: unknown key "rate" (did you mean "rate_hz"?)]
      assert {:ok, %World{sensing: %{noise: 0.5} = only_noise}} = World.parse(~s({"sensors": {"noise": 0.5}}))
      refute Map.has_key?(only_noise, :rate_hz)
      assert refused.(~s([1, 2])) =~ "the world is a JSON object"
    end

    test "a world's fields: smoke over a fire and down its plume, water toward a field, range to an obstacle" do
      here = %{lat: 40.0, lon: -7.0}
      east = fn m -> Dolphin.Geo.tangent_offset(here, 0, m) end
      still = %World{fires: [%{lat: 40.0, lon: -7.0, radius_m: 30.0, intensity: 0.8}]}
      windy = %{still | wind: %{from_deg: 270.0, speed_ms: 5.0}}
      assert_in_delta World.smoke(still, 40.0, -7.0), 0.8, 1.0e-9
      # 150 m east: nothing without wind; downwind of a west wind, the plume.
      assert World.smoke(still, east.(150).lat, east.(150).lon) < 0.001
      assert World.smoke(windy, east.(150).lat, east.(150).lon) > 0.05
      # Upwind, no plume.
      assert World.smoke(windy, east.(-150).lat, east.(-150).lon) < 0.001

      water = %World{water: %{base_celsius: 15.0, fields: [%{lat: 40.0, lon: -7.0, radius_m: 100.0, celsius: 20.0}]}}
      assert_in_delta World.water_temperature(water, 40.0, -7.0), 20.0, 1.0e-9
      assert_in_delta World.water_temperature(water, east.(1000).lat, east.(1000).lon), 15.0, 1.0e-6

      mast = %World{obstacles: [%{lat: 40.0, lon: -7.0, radius_m: 5.0, height_m: 30.0}]}
      assert_in_delta World.range(mast, east.(20).lat, east.(20).lon, 110.0, 100.0), 15.0, 0.05
      # Above its top: out of reach.
      assert World.range(mast, east.(20).lat, east.(20).lon, 140.0, 100.0) == World.range_max()
    end
  end

  describe "on a simulated vehicle" do
    setup do
      Dolphin.Test.Instance.start!()
      Clock.set_speedup(20)
      %{port: GroundStation.open()}
    end

    # A copter whose companion carries a smoke sensor, standing 10 m from a fire.
    defp smoky_copter(port) do
      home = %{lat: 40.444233, lon: -7.375234, alt: 820.0}
      fire = Dolphin.Geo.tangent_offset(home, 10, 0)
      world = %World{fires: [%{lat: fire.lat, lon: fire.lon, radius_m: 40.0, intensity: 0.9}]}
      {:ok, [id]} = Dolphin.Sim.start(gcs: port, count: 1, speedup: 20, home: home, sensors: [:smoke], world: world, sensor_noise: 0.0)
      Wait.until(fn -> match?({:ok, %{type: :uav}}, Vehicles.view(id)) end, 2_000, fn -> "vehicle #{id}" end)
      id
    end

    test "a declared named value and a message field reach the view, from the companion's component; stale, the reading is unknown", %{port: port} do
      id = smoky_copter(port)
      {:ok, smoke} = Sensors.new(:smoke, from: {:named_value, "SMOKE"}, stale_after: 2_000)
      {:ok, volts} = Sensors.new(:volts, from: {:message, :SYS_STATUS, :voltage_battery}, scale: 0.001)
      Vehicles.subscribe(id)
      :ok = Vehicles.watch_sensors([smoke, volts])

      # (A reading before the vehicle's first position has none: on a loaded
      # machine the companion may be heard first.)
      view = await_view(id, &(match?(%{position: %{}}, &1.sensors[@smoke_source]) and Map.has_key?(&1.sensors, volts.source)))
      assert %{compid: 191, value: value, position: %Dolphin.Geo.Location{}} = view.sensors[@smoke_source]
      # 0.9 at the fire's centre, 10 m away over a 40 m radius: e^(-1/16).
      assert_in_delta value, 0.9 * :math.exp(-1 / 16), 0.01
      assert_in_delta Snapshot.sensor(nil, id, smoke), value, 1.0e-9
      assert Snapshot.sensor(nil, id, volts) > 10
      assert view.sensors[volts.source].compid == 1

      # The companion falls silent (the whole vehicle does): 2 s of clock
      # time later its view says the reading is stale, with nothing else heard.
      :ok = Dolphin.Sim.set_faults(id, silence: true)
      stale = await_view(id, &match?(%{stale: [2_000]}, &1.sensors[@smoke_source]))
      assert stale.connected?
      assert Snapshot.sensor(nil, id, smoke) == nil
      assert Snapshot.sensor_age(nil, id, smoke) >= 2_000
    end

    test "the world's sensors section sets the companions' rate and noise", %{port: port} do
      home = %{lat: 40.444233, lon: -7.375234, alt: 820.0}
      fire = Dolphin.Geo.tangent_offset(home, 10, 0)
      {:ok, world} = World.parse(~s({"fires": [{"lat": #{fire.lat}, "lon": #{fire.lon}, "radius_m": 40, "intensity": 0.9}], "sensors": {"rate_hz": 10, "noise": 0}}))
      # At 1x: a simulator starved for a moment stretches the gaps in clock
      # time by the speed-up (at 20x, beside the SITL lanes, their median
      # reached 305 ms of clock time where 100 were asked for; at 5x, in a
      # fresh clone beside them, 291 ms).
      Clock.set_speedup(1)
      {:ok, [id]} = Dolphin.Sim.start(gcs: port, count: 1, speedup: 1, home: home, sensors: [:smoke], world: world)
      {:ok, smoke} = Sensors.new(:smoke, from: {:named_value, "SMOKE"})
      Vehicles.subscribe(id)
      :ok = Vehicles.watch_sensors([smoke])

      view = await_view(id, &(length(Map.get(&1.sensors, @smoke_source, %{history: []}).history) >= 11))
      {times, values, _} = view.sensors[@smoke_source].history |> Enum.take(11) |> :lists.unzip3()
      # Ten a second of vehicle time (the default is two), none noisy: the
      # same value every time. The median gap between readings, not their
      # span: a simulator starved for a moment (a loaded machine) delivers
      # a few late, then together.
      gaps = times |> Enum.chunk_every(2, 1, :discard) |> Enum.map(fn [later, earlier] -> later - earlier end) |> Enum.sort()
      assert Enum.at(gaps, 5) < 250, "readings at #{inspect(times)}"
      assert [_] = Enum.uniq(values)
    end

    test "a sensor not declared is not kept; peak and its position over a window", %{port: port} do
      id = smoky_copter(port)
      Vehicles.subscribe(id)
      {:ok, %{sensors: none}} = Vehicles.view(id)
      assert none == %{}

      {:ok, smoke} = Sensors.new(:smoke, from: {:named_value, "SMOKE"})
      :ok = Vehicles.watch_sensors([smoke])
      view = await_view(id, &(length(Map.get(&1.sensors, @smoke_source, %{history: []}).history) >= 3))
      peak = Snapshot.peak(nil, id, smoke, 60_000)
      assert peak == view.sensors[@smoke_source].history |> Enum.map(&elem(&1, 1)) |> Enum.max()
      assert %Dolphin.Geo.Location{} = Snapshot.peak_position(nil, id, smoke, 60_000)
    end

    test "a message of the user's own dialect (test/fixtures/mavlink/user) is a sensor's source like any", %{port: port} do
      alias Dolphin.MAVLink.UserDialect.SmokeSensor
      {:ok, ppm} = Sensors.new(:ppm, from: {:message, :SMOKE_SENSOR, :ppm}, stale_after: 5_000)
      assert ppm.unit == :ppm
      assert {:error, why} = Sensors.new(:ppm, from: {:message, :SMOKE_SENSR, :ppm})
      assert why =~ "did you mean SMOKE_SENSOR"
      :ok = Vehicles.watch_sensors([ppm])

      # A vehicle of its own (a socket of this test): its autopilot's heartbeat, its companion's readings.
      {:ok, socket} = :gen_udp.open(0, [:binary, ip: {127, 0, 0, 1}, active: false])
      say = fn compid, message -> :ok = :gen_udp.send(socket, {127, 0, 0, 1}, port, Dolphin.MAVLink.Frame.encode(message, sysid: 77, compid: compid, seq: 0)) end
      say.(1, %Dolphin.MAVLink.Ardupilotmega.Heartbeat{type: 2, autopilot: 3, base_mode: 0, custom_mode: 0, system_status: 4, mavlink_version: 3})
      Wait.until(fn -> match?({:ok, %{type: :uav}}, Vehicles.view(77)) end)
      Vehicles.subscribe(77)
      say.(191, %SmokeSensor{sensor_id: 1, ppm: 412.5, temperature: 2150})
      view = await_view(77, &Map.has_key?(&1.sensors, ppm.source))
      assert %{value: 412.5, compid: 191} = view.sensors[ppm.source]
      assert Snapshot.sensor(nil, 77, ppm) == 412.5
      :gen_udp.close(socket)
    end

    test "wait_for on a sensor waits while it is unknown and while below, fires on the reading above, and says so in a sensor_threshold event", %{port: port} do
      alias Dolphin.MAVLink.UserDialect.SmokeSensor
      # A vehicle of its own: its autopilot's heartbeat every 200 ms, its companion's readings when the test says.
      {:ok, socket} = :gen_udp.open(0, [:binary, ip: {127, 0, 0, 1}, active: false])
      on_exit(fn -> :gen_udp.close(socket) end)
      say = fn compid, message -> :gen_udp.send(socket, {127, 0, 0, 1}, port, Dolphin.MAVLink.Frame.encode(message, sysid: 78, compid: compid, seq: 0)) end
      heartbeat = %Dolphin.MAVLink.Ardupilotmega.Heartbeat{type: 2, autopilot: 3, base_mode: 0, custom_mode: 0, system_status: 3, mavlink_version: 3}
      spawn_link(fn -> Stream.repeatedly(fn -> say.(1, heartbeat) && Process.sleep(200) end) |> Stream.run() end)
      Wait.until(fn -> match?({:ok, %{type: :uav}}, Vehicles.view(78)) end)

      {:ok, script} =
        Script.compile_string(
          """
          use Dolphin.Script
          sensor :ppm, from: {:message, :SMOKE_SENSOR, :ppm}
          v = pick(id: 78, timeout: seconds(30))
          execute wait_for(sensor(v, :ppm) > 400)
          message("smoke at \#{sensor(v, :ppm)} ppm")
          """,
          "wait_for_smoke.exs"
        )

      on_exit(fn -> Script.purge(script) end)
      me = self()
      Dolphin.Events.subscribe()
      {:ok, pid} = Script.start(script, output: &send(me, {:output, &1}))
      assert_receive {:dolphin, :events, %{event: :task_started}}, Clock.to_real_ms(30_000)

      # Unknown (nothing heard), then heard below: the condition is not met.
      Vehicles.subscribe(78)
      say.(191, %SmokeSensor{sensor_id: 1, ppm: 300.0, temperature: 2150})
      await_view(78, &match?(%{value: 300.0}, Enum.find_value(&1.sensors, fn {_, r} -> r end)))
      refute_received {:dolphin, :events, %{event: :condition_met}}
      refute_received {:dolphin, :events, %{event: :sensor_threshold}}

      say.(191, %SmokeSensor{sensor_id: 1, ppm: 412.5, temperature: 2150})
      assert_receive {:dolphin, :events, %{event: :sensor_threshold, vehicle: 78, sensor: :ppm, value: 412.5, unit: :ppm} = event}, Clock.to_real_ms(30_000)
      assert event.condition =~ "sensor(v, :ppm) > 400"
      assert_receive {:output, "smoke at 412.5 ppm"}, Clock.to_real_ms(30_000)
      assert {:ok, %{result: :done}} = Script.await(pid, Clock.to_real_ms(30_000))
    end

    defp await_view(id, fun) do
      receive do
        {:dolphin, {:vehicle, ^id}, {:view, view}} -> if fun.(view), do: view, else: await_view(id, fun)
      after
        Clock.to_real_ms(60_000) -> flunk("vehicle #{id}: no view as expected: #{inspect(Vehicles.view(id))}")
      end
    end
  end
end
