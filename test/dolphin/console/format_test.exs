defmodule Dolphin.Console.FormatTest do
  use ExUnit.Case, async: true

  alias Dolphin.Console.Format

  describe "tables and trees" do
    test "columns are as wide as their widest cell; the right-aligned ones pad on the left" do
      text = Format.table(["ID", "NAME"], [["1", "alpha"], ["12", "b"]], [0])
      assert text == "ID  NAME\n 1  alpha\n12  b"
    end

    test "a tree draws branches and lines its states up after the widest text" do
      tree = [
        %{text: "run 1", state: "running", children: [%{text: "a", state: "x", children: []}, %{text: "bb", state: nil, children: [%{text: "c", state: "y", children: []}]}]},
        %{text: "run 2", state: nil, children: []}
      ]

      assert Format.tree(tree) ==
               String.trim_trailing("""
               run 1    running
               ├─ a     x
               └─ bb
                  └─ c  y
               run 2
               """)
    end

    test "durations and amounts read naturally" do
      assert Format.duration(850) == "850 ms"
      assert Format.duration(12_345) == "12.3 s"
      assert Format.duration(245_000) == "4m 05s"
      assert Format.duration(3_725_000) == "1h 02m"
      assert Format.battery(0.874) == "87 %"
      assert Format.battery(nil) == "-"
      assert Format.bar(0.5) == "[#####     ]"
      assert Format.bar(1.4) == "[##########]"
      assert Format.mode(:alt_hold) == "ALT_HOLD"
      assert Format.mode({:custom, 99}) == "custom 99"
      assert Format.mode(nil) == "-"
      assert Format.metres(20.04) == "20.0 m"
      assert Format.position(40.444233, -7.375234) == "40.444233, -7.375234"
      assert Format.num(:nan) == "NaN"
      assert Format.num(15.0) == "15"
    end
  end

  describe "vehicles" do
    defp row(attrs) do
      Map.merge(
        %{
          id: 1,
          type: "uav",
          airframe: "copter",
          mode: :guided,
          armed: true,
          battery: 0.87,
          lat: 40.444233,
          lon: -7.375234,
          alt: 20.0,
          link: %{received: 97, lost: 3},
          seen_ms: 120,
          lost?: false,
          activity: nil
        },
        Map.new(attrs)
      )
    end

    test "one row per vehicle with every column an operator needs" do
      text = Format.vehicles([row([]), row(id: 12, mode: :brake, armed: false, battery: nil, lost?: true, seen_ms: 23_400, link: %{received: 50, lost: 0}, activity: "picked by a script")])
      [header, one, twelve] = String.split(text, "\n")

      for column <- ~w(ID TYPE AIRFRAME MODE ARMED BATTERY POSITION ALT LINK SEEN TASK), do: assert(header =~ column)
      assert one =~ ~r/^\s+1  uav\s+copter\s+GUIDED\s+yes\s+87 %  40.444233, -7.375234  20.0 m  97 % \(3 lost\)  120 ms ago\s+-$/
      assert twelve =~ ~r/^12  uav\s+copter\s+BRAKE\s+no\s+-  .*100 %\s+LOST 23.4 s  picked by a script$/
    end

    test "a vehicle heard on more than one link: a line per path, the one in use marked" do
      paths = [
        %{via: "udpin:0.0.0.0:14551", state: :active, loss: 0.02, rtt_ms: 12, frames: 1520, in_use?: true, seen_ms: 40},
        %{via: {:radio, 2}, state: :silent, loss: nil, rtt_ms: nil, frames: 7, in_use?: false, seen_ms: 4_200}
      ]

      text = Format.vehicles([row(paths: paths), row(id: 2, paths: [hd(paths)])])
      [_header, _one, _two, title, used, silent] = String.split(text, "\n")
      assert title == "vehicle 1 paths:"
      assert used == "  *  udpin:0.0.0.0:14551  active  loss 2 %, 12 ms, 1520 frames  heard 40 ms ago"
      assert silent == "     {:radio, 2}          silent  loss ?, ? ms, 7 frames        heard 4.2 s ago"
    end

    test "no vehicles, a vehicle never heard, and link quality" do
      assert Format.vehicles([]) =~ "no vehicles known yet"
      assert Format.seen(nil, false) == "never"
      assert Format.link(nil) == "-"
      assert Format.link(%{received: 0, lost: 0}) == "-"
      assert Format.link(%{received: 1, lost: 2}) == "33 % (2 lost)"
      assert Format.link(%{received: 1, lost: 2, rtt_ms: nil, loss_in: nil, loss_out: nil}) == "33 % (2 lost)"
      assert Format.link(%{received: 9, lost: 1, rtt_ms: 44.6, loss_in: 0.1, loss_out: 0.304}) == "90 % (1 lost), 45 ms, loss in 10 % / out 30 %"
      assert Format.link(%{received: 9, lost: 0, rtt_ms: 3, loss_in: 0.0, loss_out: nil}) == "100 %, 3 ms"
    end

    test "MAV_TYPE numbers as words" do
      assert Format.type_name(2) == "quadrotor"
      assert Format.type_name(1) == "fixed wing"
      assert Format.type_name(nil) == nil
    end
  end

  describe "tasks" do
    @tasks [
      %{task_id: 3, run: 2, parent_id: nil, kind: :until, name: "until(survey, battery(v) < 0.3)", vehicle: nil},
      %{task_id: 4, run: 2, parent_id: 3, kind: :mission, name: "Survey Area", vehicle: 1},
      %{task_id: 8, run: 7, parent_id: nil, kind: :mission, name: "Patrol", vehicle: 2}
    ]

    test "scripts hold their runs, runs their task trees; leaves say their vehicle and states show" do
      groups = [%{text: "run 1 script patrol.exs", state: "running for 12.0 s", runs: [2]}]
      runs = [%{run: 2, text: "run 2"}, %{run: 7, text: "run 7 task mission \"Patrol\""}]
      text = Format.task_tree(groups, runs, @tasks, %{4 => "item 2/5"})

      assert [
               "run 1 script patrol.exs" <> s1,
               "└─ run 2",
               "   └─ 3 until \"until(survey, battery(v) < 0.3)\"" <> s3,
               "      └─ 4 mission \"Survey Area\"  vehicle 1" <> s4,
               "run 7 task mission \"Patrol\"",
               "└─ 8 mission \"Patrol\"  vehicle 2" <> s8
             ] = String.split(text, "\n")

      assert String.trim(s1) == "running for 12.0 s"
      assert String.trim(s3) == "running"
      assert String.trim(s4) == "item 2/5"
      assert String.trim(s8) == "running"
    end

    test "nothing running" do
      assert Format.task_tree([], [], [], %{}) == "no tasks running"
    end

    test "a task's state follows the events about it" do
      started = %{event: :task_started, kind: :wait_for, vehicle: nil}
      assert Format.task_state(nil, started) == "waiting"
      assert Format.task_state("waiting", %{event: :condition_met, branch: nil}) == "condition met"
      assert Format.task_state(nil, %{event: :condition_met, branch: 1}) == "branch 1 chosen"
      assert Format.task_state(nil, %{event: :task_started, kind: :mission, vehicle: 1}) == "starting"
      assert Format.task_state(nil, %{event: :task_started, kind: :sequence, vehicle: nil}) == "running"
      assert Format.task_state("starting", %{event: :task_progress, progress: %{current: 2, total: 5, reached: 1}}) == "item 2/5, reached 1"
      assert Format.task_state(nil, %{event: :task_progress, progress: %{phase: :climb}}) == "phase :climb"
      assert Format.task_state("item 2/5", %{event: :armed}) == "item 2/5"
    end
  end

  describe "one vehicle" do
    test "messages oldest first with their severity" do
      assert Format.messages([{6, "Arming motors"}, {2, "PreArm: Need Position Estimate"}]) ==
               "CRITICAL  PreArm: Need Position Estimate\nINFO      Arming motors"

      assert Format.messages([]) == "no messages"
    end

    test "the messages that came since: the new head of the list" do
      before = [{6, "b"}, {6, "a"}]
      assert Format.new_texts(before, [{2, "c"}, {6, "b"}, {6, "a"}]) == [{2, "c"}]
      assert Format.new_texts(before, before) == []
      # A repeated text is new all the same.
      assert Format.new_texts(before, [{6, "b"}, {6, "b"}, {6, "a"}]) == [{6, "b"}]
      assert Format.new_texts([], [{6, "a"}]) == [{6, "a"}]
      # The list keeps 20: the oldest fall off as new ones come.
      old = for i <- 20..1//-1, do: {6, "#{i}"}
      assert Format.new_texts(old, [{6, "21"} | Enum.take(old, 19)]) == [{6, "21"}]
    end

    test "a ticker line" do
      state = %{
        mode: :auto,
        armed: true,
        battery: 0.5,
        position: %{lat: 40.1, lon: -7.2, alt: 850.0, relative_alt: 30.04, heading: 89.6},
        mission: %{current: 2, total: 4, state: :active, reached: 1},
        landed: :in_air
      }

      line = Format.ticker(state, false, 2_500)
      assert line =~ ~r/^\s+2\.5 s  AUTO\s+ARMED\s+\[#####     \]  50 %  40\.100000, -7\.200000  alt\s+30\.0 m  hdg  90  mission 2\/4  in_air$/

      lost = Format.ticker(%{state | position: nil, mission: %{}, battery: nil, armed: false}, true, 0)
      assert lost =~ "disarmed"
      assert lost =~ "mission -"
      assert lost =~ ~r/LOST$/
    end

    test "mission items" do
      home = Dolphin.Geo.location(40.444233, -7.375234, 820)
      m = Dolphin.Mission.new("t", [Dolphin.Mission.Command.home(home), Dolphin.Mission.Command.take_off(40.444233, -7.375234, 850), Dolphin.Mission.Command.delay(5)])
      [h, t, d] = String.split(Format.items(Dolphin.Mission.to_items(m)), "\n")
      assert h =~ ~r/^\s+0 home\s+40\.4442330, -7\.3752340, 820 m AMSL/
      assert t =~ ~r/^\s+1 NAV_TAKEOFF\s+.*850 m AMSL\s+\[15, 0, 0, NaN\]/
      assert d =~ ~r/^\s+2 NAV_DELAY\s+\[5, -1, -1, -1\]/
      assert Format.items([]) == "no mission items"
    end
  end
end
