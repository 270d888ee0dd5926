defmodule Dolphin.SITL.ReassignTest do
  # `reassign` on ArduCopter: a survey whose copter is killed mid-flight is
  # taken over by a second SITL instance, which flies the passes not flown.
  # The same check as the simulator's property (test/dolphin/mission/
  # reassign_test.exs), one case. Runs ArduCopter processes and changes the
  # clock's speed-up: not async.
  use ExUnit.Case, async: false

  alias Dolphin.{Engine, Mission, SITL, Events, Vehicles}
  alias Dolphin.Mission.Command, as: C
  alias Dolphin.Mission.Resume
  alias Dolphin.Test.{Backend, Wait}

  @moduletag :sitl
  @moduletag timeout: 300_000

  # Items: 1 take-off, 2..7 the survey's three passes (2-3, 4-5, 6-7), 8 back over home.
  @passes [{2, 3}, {4, 5}, {6, 7}]
  @last 8
  @killed_after 3

  setup do
    Dolphin.Fleet.set_source({Dolphin.Fleet.MAVLinkSource, nil})
    on_exit(fn -> Dolphin.Fleet.release_all(Dolphin.Fleet, self()) end)
    :ok
  end

  # The killed instance's exit is logged: expected here.
  @tag :capture_log
  test "a copter killed mid-survey: the other flies the passes not flown, each pass once" do
    [a, b] = Backend.start(:sitl, 2)
    home = Backend.home(a)
    _ = Backend.home(b)
    for id <- [a, b], do: {:ok, _} = Dolphin.Fleet.pick(Dolphin.Fleet, self(), id: id)
    # Lost after 5 s of silence rather than the default 20.
    Vehicles.set_timeout(a, 5_000)

    survey = Mission.new("Survey", [C.home(home), C.take_off(%{home | h: home.h + 20}), C.survey_area(60, 60, 20, :north_east), C.return_home()])
    Events.subscribe()
    {:ok, run} = Engine.start(Engine.reassign(Engine.on(survey, [a]), from: [a, b]))

    seen = wait_event(&match?(%{event: :mission_item_reached, vehicle: ^a, seq: @killed_after}, &1), [])
    :ok = SITL.crash(Backend.fleet(a), a)

    assert {:ok, :done} = Engine.await(run, 240_000)
    events = Enum.reverse(seen) ++ Wait.received_events()
    Events.unsubscribe()

    assert [%{from: ^a, to: ^b, resume_seq: resume}] = for(%{event: :task_reassigned} = e <- events, do: e)
    first = MapSet.new(for %{event: :mission_item_reached, vehicle: ^a, seq: s} <- events, do: s)
    second = MapSet.new(for %{event: :mission_item_reached, vehicle: ^b, seq: s} <- events, s >= 2, do: Resume.original_seq(s, resume))

    for {p, q} <- @passes do
      flown = Enum.count([first, second], &(p in &1 and q in &1))
      assert flown == 1, "pass #{p}-#{q} flown #{flown} times (vehicle #{a}: #{inspect(first)}, vehicle #{b} from #{resume}: #{inspect(second)})"
    end

    assert @last in second
    assert Enum.all?(second, &(&1 >= resume))
  end

  # Events up to the one `fun` matches (kept, newest first).
  defp wait_event(fun, seen) do
    receive do
      {:dolphin, :events, e} -> if fun.(e), do: [e | seen], else: wait_event(fun, [e | seen])
    after
      120_000 -> flunk("event not seen; saw: #{inspect(Enum.take(seen, 5))}")
    end
  end
end
