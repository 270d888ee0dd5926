defmodule Dolphin.Sim.Copter.CameraTest do
  # The simulated camera: photos on command, by time and by distance.
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.Copter
  alias Dolphin.Sim.Copter.Camera

  @home %{lat: 40.444233, lon: -7.375234, alt: 820.0}

  defp boot(config \\ %{}), do: Copter.new(1, @home, config)
  defp captured(c), do: for({compid, %M.CameraImageCaptured{image_index: i}} <- Enum.reverse(c.out), do: {compid, i})

  defp after_ms(c, ms), do: Enum.reduce(1..div(ms, 50), c, fn _, c -> Camera.capture(%{c | time_ms: c.time_ms + 50}) end)

  test "DO_DIGICAM_CONTROL takes a photo when p5 is 1, reported by the autopilot without a camera component" do
    {0, c} = Camera.command(boot(), 203, [0, 0, 0, 0, 1.0, 0, 0])
    assert c.photos == 1 and captured(c) == [{1, 0}]
    {0, c} = Camera.command(c, 203, [0, 0, 0, 0, 0.0, 0, 0])
    assert c.photos == 1

    {0, c} = Camera.command(boot(%{camera: true}), 203, [0, 0, 0, 0, 1.0, 0, 0])
    assert captured(c) == [{100, 0}]
  end

  test "IMAGE_START_CAPTURE: one at once, then one per interval, `count` in all" do
    {0, c} = Camera.command(boot(), 2000, [0, 2.0, 3.0, 0])
    assert c.photos == 1
    c = after_ms(c, 10_000)
    assert c.photos == 3 and c.capture == nil

    # Count 0: until stopped.
    {0, c} = Camera.command(boot(), 2000, [0, 1.0, 0.0, 0])
    c = after_ms(c, 5_000)
    assert c.photos == 6
    {0, c} = Camera.command(c, 2001, [])
    assert c.photos == after_ms(c, 5_000).photos
  end

  test "DO_SET_CAM_TRIGG_DIST: a photo every so many metres flown, the first at once when p3 is 1" do
    {0, c} = Camera.command(boot(), 206, [20.0, 0, 1.0])
    assert c.photos == 1
    c = Enum.reduce(1..100, c, fn i, c -> Camera.capture(%{c | n: i * 1.0}) end)
    assert c.photos == 6

    {0, c} = Camera.command(c, 206, [0.0, 0, 0])
    assert c.capture == nil
  end

  test "other commands are unsupported" do
    assert {3, _} = Camera.command(boot(), 2500, [0, 0, 0])
  end
end
