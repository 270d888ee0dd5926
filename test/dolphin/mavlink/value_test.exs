defmodule Dolphin.MAVLink.ValueTest do
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.{Frame, Value}
  alias Dolphin.MAVLink.Ardupilotmega, as: APM

  # Floats are built from bits at run time and compared by bits: in OTP 25
  # -0.0 == 0.0 (even with ===), and the compiler may merge the two literals.
  defp f32(bits) do
    <<f::float-32>> = <<bits::32>>
    f
  end

  defp f64(bits) do
    <<f::float-64>> = <<bits::64>>
    f
  end

  defp bits(f) when is_float(f), do: {:float, <<f::float-64>>}
  defp bits(list) when is_list(list), do: Enum.map(list, &bits/1)
  defp bits(other), do: other

  # {value, its bits} as the moduledoc of Dolphin.MAVLink.Value says.
  defp float_cases do
    [
      {:nan, 0x7FC00000},
      {{:nan, 0x7FC00001}, 0x7FC00001},
      {{:nan, 0x7F800001}, 0x7F800001},
      {{:nan, 0xFFC00000}, 0xFFC00000},
      {:infinity, 0x7F800000},
      {:neg_infinity, 0xFF800000},
      {f32(0x80000000), 0x80000000},
      {f32(0), 0},
      {f32(1), 1},
      {f32(0x807FFFFF), 0x807FFFFF},
      {f32(0x7F7FFFFF), 0x7F7FFFFF}
    ]
  end

  defp double_cases do
    [
      {:nan, 0x7FF8000000000000},
      {{:nan, 0x7FF8000000000001}, 0x7FF8000000000001},
      {{:nan, 0x7FF0000000000001}, 0x7FF0000000000001},
      {{:nan, 0xFFF8000000000000}, 0xFFF8000000000000},
      {:infinity, 0x7FF0000000000000},
      {:neg_infinity, 0xFFF0000000000000},
      {f64(0x8000000000000000), 0x8000000000000000},
      {f64(1), 1},
      {f64(0x7FEFFFFFFFFFFFFF), 0x7FEFFFFFFFFFFFFF}
    ]
  end

  test "float: special values and -0.0 encode to their documented bits and decode back" do
    for {value, pattern} <- float_cases() do
      assert Value.encode(:float, nil, value) == {:ok, <<pattern::little-32>>}, "encoding #{inspect(value)}"
      assert bits(Value.decode(:float, nil, <<pattern::little-32>>)) == bits(value), "decoding #{Integer.to_string(pattern, 16)}"
    end
  end

  test "double: special values and -0.0 encode to their documented bits and decode back" do
    for {value, pattern} <- double_cases() do
      assert Value.encode(:double, nil, value) == {:ok, <<pattern::little-64>>}, "encoding #{inspect(value)}"
      assert bits(Value.decode(:double, nil, <<pattern::little-64>>)) == bits(value), "decoding #{Integer.to_string(pattern, 16)}"
    end
  end

  test "-0.0 is not 0.0 on the wire" do
    assert Value.encode(:float, nil, f32(0x80000000)) == {:ok, <<0, 0, 0, 0x80>>}
    assert Value.encode(:double, nil, f64(0x8000000000000000)) == {:ok, <<0, 0, 0, 0, 0, 0, 0, 0x80>>}
    assert Value.encode(:float, nil, f32(0)) == {:ok, <<0, 0, 0, 0>>}
  end

  test "a float beyond float32's range encodes as an infinity" do
    assert Value.encode(:float, nil, 1.0e39) == {:ok, <<0x7F800000::little-32>>}
    assert Value.encode(:float, nil, -1.0e39) == {:ok, <<0xFF800000::little-32>>}
  end

  test "special values survive a frame round trip, in scalar fields and in arrays (no NaN element is lost)" do
    specials = for {value, _} <- float_cases(), do: value
    [a, b, c, d, e, f | _] = specials

    for {msg, kinds} <- [
          {%APM.Attitude{roll: a, pitch: b, yaw: c, rollspeed: d, pitchspeed: e, yawspeed: f}, [1, 2]},
          {%APM.AttitudeQuaternionCov{q: Enum.take(specials, 4), covariance: Enum.take(specials, -9), rollspeed: f32(0x80000000)},
           [1, 2]},
          {%APM.WheelDistance{count: 16, distance: double_cases() |> Enum.map(&elem(&1, 0)) |> Stream.cycle() |> Enum.take(16)},
           [2]},
          # -0.0 as the last payload byte of a MAVLink 2 frame: its 0x80 byte is not a trailing zero.
          {%APM.Attitude{yawspeed: f32(0x80000000)}, [1, 2]}
        ],
        version <- kinds do
      bytes = Frame.encode(msg, version: version)
      assert {:ok, %Frame{message: decoded}, ""} = Frame.decode(bytes, APM)

      for {name, value} <- Map.from_struct(msg) do
        assert bits(Map.fetch!(decoded, name)) == bits(value), "#{inspect(msg.__struct__)}.#{name}, MAVLink #{version}"
      end
    end
  end

  test "an integer out of range raises an ArgumentError naming the message and the field" do
    cases = [
      {%APM.Heartbeat{type: 256}, "HEARTBEAT", "type"},
      {%APM.Heartbeat{custom_mode: -1}, "HEARTBEAT", "custom_mode"},
      {%APM.Heartbeat{custom_mode: 0x1_0000_0000}, "HEARTBEAT", "custom_mode"},
      {%APM.SysStatus{battery_remaining: 128}, "SYS_STATUS", "battery_remaining"},
      {%APM.SysStatus{battery_remaining: -129}, "SYS_STATUS", "battery_remaining"},
      {%APM.Timesync{tc1: 0x8000_0000_0000_0000}, "TIMESYNC", "tc1"},
      {%APM.Timesync{ts1: -0x8000_0000_0000_0001}, "TIMESYNC", "ts1"},
      {%APM.SystemTime{time_unix_usec: 0x1_0000_0000_0000_0000}, "SYSTEM_TIME", "time_unix_usec"},
      {%APM.BatteryStatus{voltages: [0, 0x1_0000]}, "BATTERY_STATUS", "voltages"},
      {%APM.MemoryVect{value: [-129]}, "MEMORY_VECT", "value"},
      {%APM.Heartbeat{type: 1.0}, "HEARTBEAT", "type"}
    ]

    for {msg, name, field} <- cases, version <- [1, 2] do
      error = assert_raise ArgumentError, fn -> Frame.encode(msg, version: version) end
      assert error.message =~ name and error.message =~ field, "#{inspect(msg)}: #{error.message}"
    end
  end

  test "the extremes of every integer type are accepted" do
    msg = %APM.SysStatus{
      battery_remaining: -128,
      voltage_battery: 0xFFFF,
      onboard_control_sensors_present: 0xFFFF_FFFF,
      current_battery: -0x8000
    }

    assert {:ok, %Frame{message: ^msg}, ""} = Frame.decode(Frame.encode(msg), APM)

    msg = %APM.Timesync{tc1: -0x8000_0000_0000_0000, ts1: 0x7FFF_FFFF_FFFF_FFFF}
    assert {:ok, %Frame{message: ^msg}, ""} = Frame.decode(Frame.encode(msg), APM)

    msg = %APM.SystemTime{time_unix_usec: 0xFFFF_FFFF_FFFF_FFFF, time_boot_ms: 0xFFFF_FFFF}
    assert {:ok, %Frame{message: ^msg}, ""} = Frame.decode(Frame.encode(msg), APM)

    msg = %APM.GlobalPositionInt{lat: -0x8000_0000, lon: 0x7FFF_FFFF, vx: 0x7FFF, hdg: 0xFFFF}
    assert {:ok, %Frame{message: ^msg}, ""} = Frame.decode(Frame.encode(msg), APM)

    msg = %APM.Heartbeat{type: 255, system_status: 0}
    assert {:ok, %Frame{message: ^msg}, ""} = Frame.decode(Frame.encode(msg, version: 1), APM)
  end
end
