defmodule Dolphin.EventTextTest do
  use ExUnit.Case, async: true

  alias Dolphin.EventText

  doctest Dolphin.EventText
  doctest Dolphin.CommandLineError

  describe "event lines" do
    test "every event of the catalogue has its own line" do
      values = %{
        vehicle: 1, type: :uav, mode: :guided, seq: 2, name: "Survey", items: 5, duration_ms: 30, retransmissions: 0,
        vehicles: [1, 2], requirement: "1 vehicle", reason: "why", run: 7, allocation: %{"8" => 1}, task_id: 8,
        parent_id: nil, kind: :mission, progress: %{current: 1, total: 3}, result: :done, condition: "battery(v) < 0.3",
        branch: nil, text: "hello", key: :k, value: 1, script: "x.exs", from: 1, to: 3, resume_seq: 6, held: true,
        station: :"gs1@host", heard: 2, stations: [:"gs1@host", :"gs2@host"], kept: :"gs1@host", dropped: :"gs2@host",
        path: "udpin:0.0.0.0:14550 from 10.0.0.7:14555", uid: 9, vehicle_uid: 7, other: "1@10.0.0.7:14555",
        distance: 84.9, height: 0.0, closest: 3.2, in_s: 5.1, held_ms: 4_600, action: :hold, limit_m: 20.0, limit_height_m: 10.0,
        fence: [[5003, 404_442_330, -73_752_340, 600.0]], rally: [[404_442_330, -73_745_000, 30.0]],
        sensor: :smoke, source: "NAMED_VALUE SMOKE", unit: nil, scale: 1.0, offset: 0.0, stale_after: 5_000, lat: 40.4451, lon: -7.376, h: 860.0, sent: 2
      }

      for {name, fields} <- Dolphin.Events.catalogue() do
        event = Map.merge(Map.take(values, fields), %{event: name, at_ms: 1_500})
        line = EventText.event_line(event, 1_000)
        assert line =~ ~r/^\[\s+0\.5 s\] /
        # Not the catch-all clause, which inspects the event.
        refute line =~ "%{", "#{name}: #{line}"
      end
    end

    test "lines say what happened" do
      assert EventText.event_text(%{event: :task_finished, task_id: 4, kind: :mission, name: "Survey", result: :failed, reason: "vehicle lost"}) ==
               ~s[task 4 mission "Survey": failed (vehicle lost)]

      assert EventText.event_text(%{event: :task_finished, task_id: 4, kind: :mission, name: "Survey", result: :stopped, reason: "stopped: the script halted"}) ==
               ~s[task 4 mission "Survey": stopped (the script halted)]

      assert EventText.event_text(%{event: :mode_changed, vehicle: 2, mode: :rtl}) == "vehicle 2 mode RTL"
      assert EventText.event_text(%{event: :path_changed, vehicle: 2, from: "udpin:0.0.0.0:14550", to: "udpin:0.0.0.0:14551", reason: :silent}) ==
               "vehicle 2: now through udpin:0.0.0.0:14551 (udpin:0.0.0.0:14550 went silent)"

      # As read back from an events file: strings.
      assert EventText.event_text(%{event: :path_changed, vehicle: 2, from: "a", to: "b", reason: "better"}) == "vehicle 2: now through b (better than a)"

      assert EventText.event_text(%{event: :task_reassigned, run: 7, task_id: 5, from: 1, to: 3, resume_seq: 6}) ==
               "task 5: vehicle 1 failed it; vehicle 3 takes it over from item 6"
      assert EventText.event_text(%{event: :separation_hold, vehicle: 2, other: 1, action: "aside", distance: 25.0, height: 0.0, closest: 3.2, in_s: 2.0, limit_m: 20.0, limit_height_m: 10.0}) ==
               "vehicle 2 moves out of vehicle 1's way: 25.0 m away (0.0 m in height), coming within the least separation in 2.0 s"

      assert EventText.event_text(%{event: :separation_hold, vehicle: 2, other: 1, action: :hold, distance: 84.9, height: 0.0, closest: 3.2, in_s: 5.1, limit_m: 20.0, limit_height_m: 10.0}) ==
               "vehicle 2 holds: vehicle 1 is 84.9 m away (0.0 m in height) and would come within the least separation in 5.1 s"

      assert EventText.event_text(%{event: :separation_clear, vehicle: 2, other: 1, distance: 99.9, held_ms: 4_600}) == "vehicle 2 goes on after 4.6 s held (vehicle 1 99.9 m away)"

      assert EventText.event_text(%{event: :mission_restarted, vehicle: 2, name: "North", reason: "disarmed_while_held"}) ==
               ~s[vehicle 2: "North" armed and started again (the autopilot disarmed it on the ground while it was held)]

      assert EventText.event_text(%{event: :mission_restarted, vehicle: 2, name: "North", reason: :disarmed_before_start}) ==
               ~s[vehicle 2: "North" armed and started again (the autopilot disarmed it before the mission got under way)]

      # A polygon of four corners (four items) and a circle: two zones.
      square = for _ <- 1..4, do: [5002, 404_442_330, -73_752_340, 4]

      assert EventText.event_text(%{event: :fence_applied, vehicle: 1, name: "North", fence: square ++ [[5003, 404_442_330, -73_752_340, 600.0]], rally: []}) ==
               ~s[vehicle 1: fence of "North" on (2 zone(s), 0 rally point(s))]

      assert EventText.event_text(%{event: :allocated, run: 7, allocation: %{"8" => 1, "9" => 2}}) == "run 7: task 8 on vehicle 1, task 9 on vehicle 2"
    end

    test "a platform task's lines name its vehicle" do
      started = %{event: :task_started, task_id: 3, parent_id: 1, kind: :test, name: "patrol", vehicle: 1}
      assert EventText.event_text(started) == ~s(task 3 test "patrol" started on vehicle 1)

      finished = %{event: :task_finished, task_id: 3, kind: :test, name: "patrol", vehicle: 1, result: :stopped, reason: "stopped: the run's time (--for) is over"}
      assert EventText.event_text(finished) == ~s[task 3 test "patrol" on vehicle 1: stopped (the run's time (--for) is over)]
      assert EventText.event_text(%{finished | result: :done, reason: nil}) == ~s(task 3 test "patrol" on vehicle 1: done)
    end
  end

  describe "a run's log" do
    test "messages always; with quiet nothing else" do
      for quiet <- [true, false], do: assert(EventText.logged?(%{event: :message, text: "hi"}, quiet))
      refute EventText.logged?(%{event: :picked, vehicles: [1], requirement: "1 vehicle"}, true)
      assert EventText.logged?(%{event: :picked, vehicles: [1], requirement: "1 vehicle"}, false)
    end

    test "the platform tasks as they start and end, every failure; not the bookkeeping" do
      on_vehicle = %{event: :task_finished, task_id: 3, kind: :test, name: "a", vehicle: 1, result: :done, reason: nil}
      assert EventText.logged?(on_vehicle, false)
      refute EventText.logged?(%{on_vehicle | vehicle: nil}, false)
      assert EventText.logged?(%{on_vehicle | vehicle: nil, result: :failed, reason: "boom"}, false)
      assert EventText.logged?(%{event: :task_started, task_id: 3, kind: :test, name: "a", vehicle: 1}, false)

      for name <- [:allocated, :task_progress, :signal_posted, :script_started, :script_finished],
          do: refute(EventText.logged?(%{event: name}, false), "#{name} is logged")
    end
  end
end
