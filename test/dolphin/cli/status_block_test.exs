defmodule Dolphin.CLI.StatusBlockTest do
  use ExUnit.Case, async: true

  alias Dolphin.Vehicles.View, as: Vehicle
  alias Dolphin.CLI.StatusBlock

  doctest StatusBlock

  test "a header with the clock and one line per vehicle, by id; unknowns shown as such" do
    vehicles = [
      %Vehicle{id: 3, mode: :brake, armed?: true, battery: 0.05, mission_progress: {0, 0}, relative_altitude: 12.0},
      %Vehicle{id: 1, connected?: false}
    ]

    [header, one, three] = StatusBlock.render(vehicles, %{3 => "Return to base"}, 3_723_000)
    assert header =~ "1:02:03"
    assert header =~ "2 vehicle(s)"
    assert one =~ ~r/^  1  \?\s+LOST\s+\[\?{10}\]/
    assert three =~ "BRAKE"
    assert three =~ "[#---------]   5 %"
    assert three =~ "no mission"
    assert String.ends_with?(three, "Return to base")
  end

  test "the link a vehicle heard on several is reached through, once it changed" do
    [_, line] = StatusBlock.render([%Vehicle{id: 4, mode: :auto}], %{}, 0, %{4 => "udpin:0.0.0.0:14551"})
    assert String.ends_with?(line, "link via udpin:0.0.0.0:14551")
  end

  test "a fleet larger than the block's room: the counts, the lost and the emptiest first, and how many are left out" do
    fleet = for id <- 1..1000, do: %Vehicle{id: id, armed?: true, battery: 0.5 + rem(id, 40) / 100}
    fleet = List.replace_at(fleet, 499, %Vehicle{id: 500, connected?: false})
    lines = StatusBlock.render(fleet, %{7 => "Hop"}, 0, %{}, 10)

    assert length(lines) == 10
    assert [header, counts | rest] = lines
    assert header =~ "1000 vehicle(s)"
    assert counts == "  999 armed, 1 on a task, 1 lost; battery 50..89 %"
    {shown, [last]} = Enum.split(rest, -1)
    # Vehicle 500 lost, then the 50 % ones (ids 40, 80, ...), by id.
    assert Enum.map(shown, &(&1 |> String.split() |> hd())) == ~w(40 80 120 160 200 240 500)
    assert last == "  ... and 993 more (mix dolphin.console lists them all: vehicles())"

    # Room enough: every vehicle, as always.
    assert length(StatusBlock.render(Enum.take(fleet, 9), %{}, 0, %{}, 10)) == 10
  end

  test "redraw goes up over the old block and clears it" do
    assert IO.iodata_to_binary(StatusBlock.redraw(3, ["a", "b"])) == "\e[3A\r\e[Ja\nb\n"
    assert IO.iodata_to_binary(StatusBlock.redraw(0, ["a"])) == "\r\e[Ja\n"
    assert StatusBlock.erase(0) == []
  end
end
