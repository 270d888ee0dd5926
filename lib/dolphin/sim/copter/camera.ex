defmodule Dolphin.Sim.Copter.Camera do
  @moduledoc false
  # The simulated copter's camera: photos taken on command, every so many
  # seconds or metres, counted and reported (CAMERA_IMAGE_CAPTURED) by the
  # camera component when the vehicle has one, else by the autopilot
  # (ArduPilot's camera library).

  import Dolphin.Sim.Copter, only: [say: 3, distance_to: 3]

  alias Dolphin.Sim.{Copter, Streams}

  @autopilot 1
  @camera 100

  # MAV_RESULT
  @accepted 0
  @unsupported 3

  # A camera command (DO_DIGICAM_CONTROL, DO_SET_CAM_TRIGG_DIST,
  # IMAGE_START_CAPTURE, IMAGE_STOP_CAPTURE) with its seven parameters.
  @spec command(Copter.t(), non_neg_integer(), [number()]) :: {0 | 3, Copter.t()}
  def command(c, 203, [_, _, _, _, p5 | _]) do
    if round(p5) == 1, do: {@accepted, photo(c)}, else: {@accepted, c}
  end

  def command(c, 206, [p1, _p2, p3 | _]) do
    c = if p1 > 0, do: %{c | capture: {:distance, p1 * 1.0, {c.n, c.e}}}, else: %{c | capture: nil}
    c = if round(p3) == 1 and p1 > 0, do: photo(c), else: c
    {@accepted, c}
  end

  def command(c, 2000, [_p1, interval, count | _]) do
    c =
      cond do
        interval <= 0 or round(count) == 1 -> photo(c)
        true -> %{c | capture: {:interval, interval * 1000, c.time_ms + interval * 1000, if(count <= 0, do: :infinity, else: round(count) - 1)}} |> photo()
      end

    {@accepted, c}
  end

  def command(c, 2001, _params), do: {@accepted, %{c | capture: nil}}
  def command(c, _command, _params), do: {@unsupported, c}

  defp photo(c) do
    c = %{c | photos: c.photos + 1}
    compid = if c.config.camera, do: @camera, else: @autopilot
    say(c, Streams.image_captured(c), compid)
  end

  # The photos due after a step: the next of a series in time, or the
  # distance flown since the last one.
  @spec capture(Copter.t()) :: Copter.t()
  def capture(%{capture: {:interval, every, next, left}} = c) when c.time_ms >= next do
    c = photo(c)
    left = if left == :infinity, do: left, else: left - 1
    if left == 0, do: %{c | capture: nil}, else: %{c | capture: {:interval, every, next + every, left}}
  end

  def capture(%{capture: {:distance, every, {n0, e0}}} = c) do
    if distance_to(c, n0, e0) >= every,
      do: photo(%{c | capture: {:distance, every, {c.n, c.e}}}),
      else: c
  end

  def capture(c), do: c
end
