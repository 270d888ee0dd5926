defmodule Dolphin.MAVLink.MissionItemsTest do
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.MissionItems

  doctest MissionItems

  test "local frames scale metres by 1e4; what an integer cannot hold becomes 0" do
    assert %M.MissionItemInt{x: 12_500, y: -30_000} = MissionItems.to_int(%M.MissionItem{frame: 1, x: 1.25, y: -3.0})
    assert %M.MissionItemInt{x: 0, y: 0} = MissionItems.to_int(%M.MissionItem{frame: 3, x: :nan, y: :infinity})
    assert %M.MissionItem{x: 1.25} = MissionItems.to_float(%M.MissionItemInt{frame: 1, x: 12_500})
  end
end
