defmodule Dolphin.Vehicles.ViewsTest do
  use ExUnit.Case, async: false

  alias Dolphin.Fleet.FakeSource
  alias Dolphin.Vehicles
  alias Dolphin.Vehicles.{View, Views}

  doctest Dolphin.Vehicles.View, only: [transitions: 2]
  doctest Dolphin.Vehicles.Vehicle, only: [lost_after_ms: 2]

  # A vehicle no process of this node owns (as one heard by another node would be).
  @id 241

  setup do
    on_exit(fn -> Vehicles.forget(@id) end)
    Dolphin.Events.subscribe()
    Vehicles.subscribe(:all)
    Vehicles.subscribe(@id)
    :ok
  end

  test "a view put without a local vehicle process is read, listed, published and announced" do
    assert Views.get(@id) == {:error, :unknown_vehicle}
    view = %View{id: @id, type: :uav, battery: 0.9, mode: :guided}
    :ok = Views.put(view)

    assert Views.get(@id) == {:ok, view}
    assert Vehicles.view(@id) == {:ok, view}
    assert @id in Views.ids() and @id in Vehicles.list()
    assert view in Views.all()
    assert_receive {:dolphin, {:vehicle, @id}, {:view, ^view}}
    assert_receive {:dolphin, :events, %{event: :vehicle_discovered, vehicle: @id, type: :uav}}
    assert_receive {:dolphin, :vehicles, {:vehicle_changed, @id}}

    # A change of battery and mode: published, announced, but nothing picks match on.
    :ok = Views.put(%{view | battery: 0.8, mode: :auto})
    assert_receive {:dolphin, {:vehicle, @id}, {:view, %View{battery: 0.8}}}
    assert_receive {:dolphin, :events, %{event: :mode_changed, vehicle: @id, mode: :auto}}
    refute_received {:dolphin, :vehicles, {:vehicle_changed, @id}}

    :ok = Views.put(%{view | mode: :auto, connected?: false})
    assert_receive {:dolphin, :events, %{event: :vehicle_lost, vehicle: @id}}
    assert_receive {:dolphin, :vehicles, {:vehicle_changed, @id}}

    # Forgotten: no row, an event; put again, it is discovered anew.
    :ok = Vehicles.forget(@id)
    assert_receive {:dolphin, :vehicles, {:vehicle_forgotten, @id}}
    assert Views.get(@id) == {:error, :unknown_vehicle}
    refute @id in Vehicles.list()
    :ok = Views.put(view)
    assert_receive {:dolphin, :events, %{event: :vehicle_discovered, vehicle: @id}}
  end

  test "a vehicle whose type is unknown is announced once it is known" do
    :ok = Views.put(%View{id: @id, mode: :stabilize})
    :ok = Views.put(%View{id: @id, mode: :guided})
    :ok = Views.put(%View{id: @id, type: :usv, mode: :guided})
    assert_receive {:dolphin, :events, %{event: :vehicle_discovered, vehicle: @id, type: :usv}}
    refute_received {:dolphin, :events, %{event: :mode_changed, vehicle: @id}}
  end

  test "the notices on :vehicles follow from the views, each after the view that shows it" do
    :ok = Views.put(%View{id: @id, mode: :stabilize})
    refute_received {:dolphin, :vehicles, {:vehicle_discovered, @id}}
    :ok = Views.put(%View{id: @id, type: :uav})
    :ok = Views.put(%View{id: @id, type: :uav, connected?: false})
    :ok = Views.put(%View{id: @id, type: :uav, connected?: false, battery: 0.5})
    :ok = Views.put(%View{id: @id, type: :uav, battery: 0.5})
    :ok = Views.delete(@id)
    :ok = Views.delete(@id)

    notices =
      for {:dolphin, topic, what} <- messages(), topic in [{:vehicle, @id}, :vehicles], what != {:vehicle_changed, @id} do
        case what do
          {:view, view} -> {:view, view.type, view.connected?}
          notice -> notice
        end
      end

    assert notices == [
             {:view, nil, true},
             {:view, :uav, true},
             {:vehicle_discovered, @id},
             {:view, :uav, false},
             {:vehicle_lost, @id},
             {:view, :uav, false},
             {:view, :uav, true},
             {:vehicle_reconnected, @id},
             {:vehicle_forgotten, @id}
           ]
  end

  # The events file of a run is closed at the script's end, which a reader of
  # the view may bring about (a landing mission ends on the disarm): its
  # events must reach a subscriber before the view does.
  test "a view's events come before the view itself, in every subscriber's mailbox" do
    :ok = Views.put(%View{id: @id, type: :uav, armed?: true})
    _ = messages()
    :ok = Views.put(%View{id: @id, type: :uav, armed?: false})

    order = for {:dolphin, topic, what} <- messages(), topic in [{:vehicle, @id}, :events], do: if(topic == :events, do: what.event, else: :view)
    assert order == [:disarmed, :view]
  end

  defp messages do
    receive do
      message -> [message | messages()]
    after
      0 -> []
    end
  end

  test "a put that is not a view is a caller mistake" do
    assert_raise ArgumentError, ~r/a view is a %Dolphin.Vehicles.View{} with a vehicle id, got: %{id: 3}/, fn -> Views.put(%{id: 3}) end
  end

  test "a test source's vehicles are announced the same way, or quietly with events: false" do
    loud = :"views_loud_#{System.unique_integer([:positive])}"
    quiet = :"views_quiet_#{System.unique_integer([:positive])}"
    start_supervised!({FakeSource, name: loud}, id: loud)
    start_supervised!({FakeSource, name: quiet, events: false}, id: quiet)
    [a, b] = for _ <- 1..2, do: 300_000 + System.unique_integer([:positive, :monotonic])

    FakeSource.add(quiet, b, type: :uav)
    FakeSource.set(quiet, b, mode: :guided)
    FakeSource.add(loud, a, type: :uav)
    FakeSource.set(loud, a, mode: :guided)
    assert_receive {:dolphin, :events, %{event: :vehicle_discovered, vehicle: ^a}}
    assert_receive {:dolphin, :events, %{event: :mode_changed, vehicle: ^a, mode: :guided}}
    refute_received {:dolphin, :events, %{vehicle: ^b}}
    assert [%View{id: ^b, mode: :guided}] = FakeSource.views(quiet)
    # Quiet in the events, not in the notices.
    assert_received {:dolphin, :vehicles, {:vehicle_discovered, ^b}}
    FakeSource.lose(quiet, b)
    assert_received {:dolphin, :vehicles, {:vehicle_lost, ^b}}
    FakeSource.reconnect(quiet, b)
    assert_received {:dolphin, :vehicles, {:vehicle_reconnected, ^b}}
    FakeSource.remove(quiet, b)
    assert_received {:dolphin, :vehicles, {:vehicle_forgotten, ^b}}
    assert_raise ArgumentError, ~r/events: must be true or false, got: :yes/, fn -> FakeSource.start_link(name: :views_bad, events: :yes) end
  end
end
