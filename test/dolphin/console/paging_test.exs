defmodule Dolphin.Console.PagingTest do
  # vehicles() of a fleet larger than a page: 50 rows at a time, in id order,
  # and a line that says which and how to see the rest. Fake vehicles of
  # the fleet's source, in an instance of this test's own: async.
  use ExUnit.Case, async: true

  import ExUnit.CaptureIO

  alias Dolphin.Fleet.FakeSource

  doctest Dolphin.Console.Format, only: [page_line: 4]

  setup do
    Dolphin.Test.Instance.start!()
    name = :"paging_fakes_#{System.unique_integer([:positive])}"
    start_supervised!({FakeSource, name: name})
    for id <- 1..120, do: FakeSource.add(name, id, type: :uav, airframe: :copter)
    :ok = Dolphin.Fleet.set_source(FakeSource.source(name))
    :ok
  end

  defp ids_shown(text), do: for([id | _] <- text |> String.split("\n") |> Enum.map(&String.split/1), Integer.parse(id) != :error, do: String.to_integer(id))

  test "a page at a time, the last one short, every one on asking, a page beyond the last said to be none" do
    first = capture_io(fn -> Dolphin.Console.vehicles() end)
    assert ids_shown(first) == Enum.to_list(1..50)
    assert first =~ "vehicles 1-50 of 120 (page 1 of 3): vehicles(2) for the next, vehicles(:all) for every one"

    last = capture_io(fn -> Dolphin.Console.vehicles(3) end)
    assert ids_shown(last) == Enum.to_list(101..120)
    assert last =~ "vehicles 101-120 of 120 (page 3 of 3): vehicles(:all) for every one"

    assert ids_shown(capture_io(fn -> Dolphin.Console.vehicles(:all) end)) == Enum.to_list(1..120)
    assert capture_io(fn -> Dolphin.Console.vehicles(4) end) =~ "no page 4: 120 vehicle(s), 3 page(s) of 50 (vehicles(:all) shows every one)"
    assert capture_io(fn -> Dolphin.Console.vehicles(0) end) =~ "vehicles/1 takes a page number (1, 2, ...) or :all, not 0"
  end

  test "a fleet of one page is shown whole, and a page beyond it said to be none" do
    name = :"paging_few_#{System.unique_integer([:positive])}"
    start_supervised!({FakeSource, name: name}, id: :few)
    for id <- 1..3, do: FakeSource.add(name, id, type: :uav, airframe: :copter)
    :ok = Dolphin.Fleet.set_source(FakeSource.source(name))
    shown = capture_io(fn -> Dolphin.Console.vehicles() end)
    assert ids_shown(shown) == [1, 2, 3]
    refute shown =~ "page"
    assert capture_io(fn -> Dolphin.Console.vehicles(2) end) =~ "no page 2: 3 vehicle(s), 1 page(s) of 50"
  end
end
