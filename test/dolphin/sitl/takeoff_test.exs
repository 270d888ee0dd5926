defmodule Dolphin.SITL.TakeoffTest do
  # A mission's take-off to the height the copter already stands at, on
  # ArduCopter SITL and on the simulator: ArduCopter raises a take-off from
  # the ground to at least 1 m above it (ModeAuto::takeoff_start), completes
  # it there and flies on; the simulator must do the same. (NAV_TAKEOFF's
  # pitch, here 860°, is ArduPlane's: ArduCopter ignores it.)
  use ExUnit.Case, async: false

  alias Dolphin.{Engine, Mission}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Mission.Command, as: C
  alias Dolphin.Test.{Backend, FrameRecorder}

  @moduletag :sitl
  @moduletag timeout: 300_000

  setup do
    Dolphin.Fleet.set_source({Dolphin.Fleet.MAVLinkSource, nil})
    :ok
  end

  defp ground_take_off(home) do
    Mission.new("ground take-off")
    |> Mission.add(C.home(home))
    |> Mission.add(C.take_off(home, 860))
    |> Mission.add(C.move(40, 0, 20))
    |> Mission.add(C.return_home_and_land())
  end

  # Flies the mission to its end; the most it climbed (metres above home)
  # before it reported the take-off reached.
  defp fly(backend) do
    {:ok, recorder} = FrameRecorder.start_link()
    [id] = Backend.start(backend, 1, forward: [FrameRecorder.endpoint(recorder)])
    home = Backend.home(id)
    {:ok, _} = Dolphin.Fleet.pick(Dolphin.Fleet, self(), id: id)

    assert {:ok, :done} = Engine.run(Engine.on(ground_take_off(home), [id])), "#{backend}"

    own = for {_t, ^id, m} <- FrameRecorder.frames(recorder), do: m
    {before, [_reached | _]} = Enum.split_while(own, &(not match?(%M.MissionItemReached{seq: 1}, &1)))
    heights = for %M.GlobalPositionInt{relative_alt: mm} <- before, do: mm / 1000
    Backend.stop([id])
    Enum.max(heights)
  end

  test "a take-off to the ground's own height ends within 2 m of the ground and the mission flies on, on ArduCopter and on the simulator" do
    for backend <- [:sitl, :sim] do
      most = fly(backend)
      assert most <= 2.0, "#{backend}: climbed to #{most} m before the take-off was reached"
    end
  end
end
