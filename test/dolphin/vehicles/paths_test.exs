defmodule Dolphin.Vehicles.PathsTest do
  # The paths to one vehicle as pure functions: de-duplication (with
  # properties), figures per path, and the choice of the path in use.
  use ExUnit.Case, async: true

  import Dolphin.Property

  alias Dolphin.MAVLink.Frame
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Vehicles.{LinkQuality, Paths}

  doctest Paths

  # A frame whose bytes are its component, sequence number and message id:
  # after a wrap, the same message at the same number has the same bytes.
  defp frame(seq, msgid \\ 0, compid \\ 1), do: %Frame{compid: compid, seq: seq, msgid: msgid, raw: <<compid, seq, msgid::24>>}

  defp feed(paths, events), do: Enum.map_reduce(events, paths, fn {via, f, t}, p -> Paths.heard(p, via, f, t, t) end)

  # The paths of one vehicle first heard on `first`, then heard once on each
  # of `others` (a frame of component 250, which no test uses otherwise) and
  # identified as the vehicle's: both autopilots report unique id 7.
  defp vehicle([first | others]) do
    Enum.reduce(others, Paths.new(first, 0, 0) |> Paths.identified(first, 7), fn via, p ->
      {:unidentified, p} = Paths.heard(p, via, frame(0, 0, 250), 0, 0)
      {p, [{^via, :same}]} = p |> Paths.identified(via, 7) |> Paths.settle(0, 0)
      p
    end)
  end

  describe "de-duplication" do
    test "a copy on another path is a duplicate, counted for its path" do
      p = vehicle([:a, :b])
      {verdicts, p} = feed(p, [{:a, frame(0), 1}, {:b, frame(0), 5}, {:b, frame(1), 6}, {:a, frame(1), 8}])
      assert verdicts == [:fresh, :duplicate, :fresh, :duplicate]
      # b's first frame was the one it was identified with.
      assert Enum.map(Paths.list(p), &{&1.via, &1.frames}) == [{:a, 2}, {:b, 3}]
    end

    test "the same frame again on the same path is fresh (a network's duplicate, a reboot)" do
      {verdicts, _} = feed(vehicle([:a, :b]), [{:a, frame(0), 1}, {:a, frame(0), 2}, {:b, frame(0), 3}, {:b, frame(0), 4}])
      assert verdicts == [:fresh, :fresh, :duplicate, :fresh]
    end

    test "other components, other bytes, or too late are not copies" do
      {verdicts, _} =
        feed(vehicle([:a, :b]), [
          {:a, frame(0, 0, 1), 0},
          {:b, frame(0, 0, 2), 1},
          {:b, frame(0, 7, 1), 2},
          {:a, frame(1), 3},
          {:b, frame(1), 2_000}
        ])

      assert verdicts == [:fresh, :fresh, :fresh, :fresh, :fresh]
    end

    test "a vehicle heard on one path: every frame is fresh, whatever repeats" do
      gen = :proper_types.list({:proper_types.integer(0, 3), :proper_types.integer(0, 255), :proper_types.integer(0, 2)})

      check(
        forall(gen, fn frames ->
          events = frames |> Enum.with_index() |> Enum.map(fn {{compid, seq, msgid}, t} -> {:a, frame(seq, msgid, compid), t} end)
          {verdicts, _} = feed(Paths.new(:a, 0, 0), events)
          assert Enum.all?(verdicts, &(&1 == :fresh))
        end),
        numtests: 200
      )
    end

    test "two paths, each losing frames, one behind the other: every frame is fresh once, across wraps" do
      # Per frame: heard on a, on b, or both; b lags `lag` frames behind a.
      gen = {:proper_types.integer(0, 20), :proper_types.non_empty(:proper_types.list({:proper_types.oneof([:a, :b, :both]), :proper_types.integer(0, 2)}))}

      check(
        forall(gen, fn {lag, heard} ->
          # Long enough to wrap several times, in ms of real time (a wrap in 256 ms).
          heard = heard |> Stream.cycle() |> Enum.take(max(length(heard), 700))

          events =
            heard
            |> Enum.with_index()
            |> Enum.flat_map(fn {{on, msgid}, i} ->
              f = frame(rem(i, 256), msgid)
              a = if on in [:a, :both], do: [{2 * i, {:a, f, i}}], else: []
              b = if on in [:b, :both], do: [{2 * (i + lag) + 1, {:b, f, i + lag}}], else: []
              a ++ b
            end)
            |> Enum.sort_by(&elem(&1, 0))
            |> Enum.map(&elem(&1, 1))

          {verdicts, _} = feed(vehicle([:a, :b]), events)
          assert Enum.count(verdicts, &(&1 == :fresh)) == length(heard)
          assert Enum.count(verdicts, &(&1 == :duplicate)) == Enum.count(heard, &(elem(&1, 0) == :both))
        end),
        numtests: 100
      )
    end
  end

  describe "figures per path" do
    test "loss from each path's own sequence numbers; TIMESYNC answers only for their path" do
      p = vehicle([:a, :b])
      # a hears every frame, b every other one.
      {_, p} = feed(p, for(i <- 0..39, via <- [:a, :b], via == :a or rem(i, 2) == 0, do: {via, frame(i), i}))
      {[a: 100, b: 101], p} = Paths.timesync(p, 100, 50)
      p = Paths.measure(p, 50, 2_000)
      assert [%{via: :a, loss: 0.0}, %{via: :b, loss: b_loss}] = Paths.list(p)
      assert_in_delta b_loss, 0.5, 0.03

      answer = fn ts1, seq -> %Frame{compid: 1, seq: seq, msgid: 111, message: %M.Timesync{tc1: 1, ts1: ts1}, raw: <<seq, ts1>>} end
      # a's answer heard on b does not count for b, nor for a.
      {_, p} = feed(p, [{:b, answer.(100, 40), 60}, {:a, answer.(101, 41), 61}, {:b, answer.(101, 42), 75}])
      assert [%{via: :a, rtt_ms: nil}, %{via: :b, rtt_ms: 25}] = Paths.list(p)
    end
  end

  describe "the path in use" do
    defp with_quality(p, via, loss_rt, rtt) do
      # The latest 20 TIMESYNCs, that many unanswered.
      lost = round(loss_rt * 20)
      q = %{LinkQuality.new() | loss_rt: loss_rt, rtt_ms: rtt, outcomes: List.duplicate(false, lost) ++ List.duplicate(true, 20 - lost)}
      put_in(p.paths[via].quality, q)
    end

    defp heard_at(p, via, t), do: p |> Paths.heard(via, frame(rem(t, 256), 0, via_compid(via)), t, t) |> elem(1)
    defp via_compid(:a), do: 1
    defp via_compid(:b), do: 2
    defp via_compid(:c), do: 3

    test "a path in use that goes silent is replaced by the best heard one" do
      p = vehicle([:a, :b, :c]) |> heard_at(:b, 10) |> heard_at(:c, 10) |> with_quality(:b, 0.2, 40) |> with_quality(:c, 0.0, 90)
      assert {p, nil} = Paths.judge(p, 1_000, 1_000)
      assert Enum.map(Paths.list(p), &{&1.via, &1.state}) == [a: :active, b: :standby, c: :standby]

      p = p |> heard_at(:b, 1_400) |> heard_at(:c, 1_400)
      assert {p, {:a, :c, :silent}} = Paths.judge(p, 1_600, 1_600)
      assert Paths.in_use(p) == :c
      assert Enum.map(Paths.list(p), &{&1.via, &1.state}) == [c: :active, a: :silent, b: :standby]

      # Heard again: standby, and not taken back for being as good.
      p = heard_at(p, :a, 1_700)
      assert {p, nil} = Paths.judge(p, 1_800, 1_800)
      assert Enum.map(Paths.list(p), &{&1.via, &1.state}) == [c: :active, a: :standby, b: :standby]
    end

    test "silence needs 1.5 s of clock time and a real-time floor" do
      # 2 s of clock time but only 100 ms of real time (a speed-up of 20): not silent yet.
      {:fresh, p} = Paths.heard(vehicle([:a, :b]), :b, frame(0, 0, 2), 2_000, 100)
      assert {_, nil} = Paths.judge(p, 2_000, 100)
      assert {_, {:a, :b, :silent}} = Paths.judge(p, 2_000, 250)
    end

    test "an address a link no longer hears the vehicle from is forgotten; a silent link is not" do
      p = vehicle([{:l1, {{10, 0, 0, 1}, 1}}, {:l2, {{10, 0, 0, 2}, 1}}])
      # The vehicle comes back on link 1 from another port: the vehicle once
      # its autopilot says so, then the path in use.
      {:unidentified, p} = Paths.heard(p, {:l1, {{10, 0, 0, 1}, 2}}, frame(1), 5_000, 5_000)
      {p, nil} = Paths.judge(p, 5_000, 5_000)
      {p, [_]} = p |> Paths.identified({:l1, {{10, 0, 0, 1}, 2}}, 7) |> Paths.settle(5_000, 5_000)
      {p, _} = Paths.judge(p, 5_000, 5_000)
      assert Paths.in_use(p) == {:l1, {{10, 0, 0, 1}, 2}}
      assert length(Paths.list(Paths.forget_silent(p, 20_000, 20_000))) == 3
      assert [{:l1, {_, 2}}, {:l2, _}] = p |> Paths.forget_silent(20_001, 20_000) |> Paths.list() |> Enum.map(& &1.via)
    end

    test "every path silent: the path in use stays" do
      p = vehicle([:a, :b]) |> heard_at(:b, 0)
      assert {p, nil} = Paths.judge(p, 5_000, 5_000)
      assert Paths.in_use(p) == :a
      assert Enum.map(Paths.list(p), & &1.state) == [:silent, :silent]
    end

    test "another path takes over only when clearly better" do
      p = vehicle([:a, :b]) |> heard_at(:b, 0)
      # Judged at 100 ms and again 2 s of real time later (heard in between).
      twice = fn p ->
        {p, nil} = Paths.judge(p, 100, 100)
        p = p |> heard_at(:a, 1_000) |> heard_at(:b, 1_000)
        Paths.judge(p, 1_100, 2_100)
      end

      assert {_, nil} = p |> with_quality(:a, 0.10, 50) |> with_quality(:b, 0.07, 30) |> twice.()
      assert {_, {:a, :b, :better}} = p |> with_quality(:a, 0.10, 50) |> with_quality(:b, 0.0, 60) |> twice.()
      assert {_, nil} = p |> with_quality(:a, 0.0, 50) |> with_quality(:b, 0.0, 30) |> twice.()
      assert {_, {:a, :b, :better}} = p |> with_quality(:a, 0.0, 80) |> with_quality(:b, 0.0, 20) |> twice.()
      # A share of few outcomes is no evidence: one lost of the first five.
      few = fn p, via, outcomes -> put_in(p.paths[via].quality, %{LinkQuality.new() | loss_rt: 0.2, rtt_ms: 50, outcomes: outcomes}) end
      assert {_, nil} = p |> few.(:a, [false, true, true, true, true]) |> with_quality(:b, 0.0, 50) |> twice.()
      # Better for less than 2 s: not yet.
      {p, nil} = p |> with_quality(:a, 0.0, 80) |> with_quality(:b, 0.0, 20) |> Paths.judge(100, 100)
      assert {p, nil} = Paths.judge(p, 200, 1_000)
      # Not better for a moment: the 2 s start again.
      {p, nil} = p |> with_quality(:b, 0.0, 79) |> Paths.judge(300, 1_500)
      assert {_, nil} = p |> with_quality(:b, 0.0, 20) |> Paths.judge(400, 2_200)
    end

    test "two equal paths whose figures wobble do not take turns" do
      gen = :proper_types.list({:proper_types.integer(0, 4), :proper_types.integer(0, 4), :proper_types.integer(40, 55), :proper_types.integer(40, 55)})

      check(
        forall(gen, fn wobbles ->
          p = vehicle([:a, :b]) |> heard_at(:b, 0)

          Enum.reduce(wobbles, p, fn {la, lb, ra, rb}, p ->
            {p, change} = p |> with_quality(:a, la / 100, ra) |> with_quality(:b, lb / 100, rb) |> Paths.judge(10, 10)
            assert change == nil
            p
          end)
        end),
        numtests: 200
      )
    end
  end

  describe "another vehicle with the same system id" do
    test "a new path is pending: its frames are not the vehicle's, it is never used, it is asked for its uid" do
      {:fresh, p} = Paths.heard(Paths.new(:a, 0, 0), :a, frame(0), 0, 0)
      # The vehicle's own id is asked from its discovery on.
      assert {[:a], p} = Paths.identity_asks(p, 0, 0)
      {:unidentified, p} = Paths.heard(p, :b, frame(1), 10, 10)
      # The same frame on both: not a copy (b may be another vehicle's).
      {:unidentified, p} = Paths.heard(p, :b, frame(0), 20, 20)
      {:fresh, p} = Paths.heard(p, :a, frame(1), 30, 30)
      assert [%{via: :a, identity: :same}, %{via: :b, identity: :pending, uid: nil}] = Paths.list(p)

      # Both asked (a again: its id is not known yet), then a second of clock
      # time apart, and half a second of real time, then one, then two...
      assert {[:b, :a], p} = Paths.identity_asks(p, 30, 30)
      assert {[], p} = Paths.identity_asks(p, 500, 500)
      assert {[:b, :a], p} = Paths.identity_asks(p, 1_030, 530)
      assert {p, []} = Paths.settle(p, 1_030, 530)
      p = Paths.identified(p, :a, 7)
      assert Paths.uid(p) == 7
      assert {[], p} = Paths.identity_asks(p, 2_030, 1_029)
      assert {[:b], p} = Paths.identity_asks(p, 2_030, 1_530)
      assert {[], p} = Paths.identity_asks(p, 3_030, 3_529)
      assert {[:b], p} = Paths.identity_asks(p, 3_030, 3_530)

      # The path in use silent, b heard: a stays (b is not known to be the vehicle).
      {:unidentified, p} = Paths.heard(p, :b, frame(2), 5_000, 5_000)
      assert {p, nil} = Paths.judge(p, 5_000, 5_000)
      assert Paths.in_use(p) == :a
      assert {_, []} = Paths.settle(p, 5_000, 5_000)
    end

    test "the vehicle's own id unknown and its path in use quiet (a reboot onto a new port): a new path that answers joins" do
      {:unidentified, p} = Paths.heard(Paths.new(:a, 0, 0), :b, frame(0, 0, 2), 16_000, 16_000)
      assert {_, [b: :unidentifiable]} = p |> Paths.identified(:b, 9) |> Paths.settle(16_000, 16_000)
    end

    test "the path in use quiet for two heartbeats (a loaded host): a new path waits for the vehicle's own id" do
      {:unidentified, p} = Paths.heard(Paths.new(:a, 0, 0), :b, frame(0, 0, 2), 2_000, 2_000)
      p = Paths.identified(p, :b, 9)
      assert {p, []} = Paths.settle(p, 2_500, 2_500)
      # Heard again, and its id another one: another vehicle.
      {:fresh, p} = Paths.heard(p, :a, frame(1), 2_600, 2_600)
      assert {_, [b: {:refused, 9, 7}]} = p |> Paths.identified(:a, 7) |> Paths.settle(2_700, 2_700)
    end

    test "two unique ids: another vehicle, refused for good and sent nothing" do
      {:unidentified, p} = Paths.heard(Paths.new(:a, 0, 0), :b, frame(0, 0, 2), 0, 0)
      {p, [b: {:refused, 9, 7}]} = p |> Paths.identified(:a, 7) |> Paths.identified(:b, 9) |> Paths.settle(0, 0)
      assert [%{via: :a}, %{via: :b, identity: :refused, uid: 9}] = Paths.list(p)
      assert {:unidentified, p} = Paths.heard(p, :b, frame(1, 0, 2), 10, 10)
      assert {[], p} = Paths.identity_asks(p, 5_000, 5_000)
      assert {[a: 100], _} = Paths.timesync(p, 100, 10)
      # Nothing more to decide, ever.
      assert {_, []} = Paths.settle(p, 100_000, 100_000)
    end

    test "the same unique id: the same vehicle; none to compare: taken for the same" do
      {:unidentified, p} = Paths.heard(Paths.new(:a, 0, 0), :b, frame(0, 0, 2), 0, 0)
      # b answered first: decided once a's uid is known.
      p = Paths.identified(p, :b, 7)
      assert {p, []} = Paths.settle(p, 0, 0)
      {p, [b: :same]} = p |> Paths.identified(:a, 7) |> Paths.settle(0, 0)
      assert {:fresh, _} = Paths.heard(p, :b, frame(1, 0, 2), 10, 10)

      # An autopilot without a unique id reports 0.
      {:unidentified, p} = Paths.heard(Paths.new(:a, 0, 0), :b, frame(0, 0, 2), 0, 0)
      assert {_, [b: :unidentifiable]} = p |> Paths.identified(:a, 7) |> Paths.identified(:b, 0) |> Paths.settle(0, 0)

      # No answer: asked 5 times, 1, 1, 2 and 4 s apart (at speed-up 1),
      # then 8 s more, then taken for the same.
      {:unidentified, p} = Paths.heard(Paths.new(:a, 0, 0), :b, frame(0, 0, 2), 0, 0)

      p =
        [0, 1_000, 2_000, 4_000, 8_000]
        |> Enum.with_index()
        |> Enum.reduce(p, fn {t, k}, p ->
          # (a heard all along: its silence would end the wait.)
          {:fresh, p} = Paths.heard(p, :a, frame(k), t, t)
          assert {[:b, :a], p} = Paths.identity_asks(p, t, t)
          assert {p, []} = Paths.settle(p, t, t)
          p
        end)

      {:fresh, p} = Paths.heard(p, :a, frame(5), 15_000, 15_000)
      assert {[], p} = Paths.identity_asks(p, 15_000, 15_000)
      assert {p, []} = Paths.settle(p, 15_000, 15_000)
      # a, asked for as long as b waits for it (8 s apart now); b given up on.
      assert {[:a], p} = Paths.identity_asks(p, 16_000, 16_000)
      assert {p, [b: :unidentifiable]} = Paths.settle(p, 16_000, 16_000)
      assert [%{identity: :same}, %{identity: :same}] = Paths.list(p)
      # Nothing waits for a's id any more: its 5 asks and this one were all;
      # b, taken for the vehicle's for want of an answer, is asked on.
      assert {[:b], _} = Paths.identity_asks(p, 60_000, 60_000)
    end

    test "a path taken for the vehicle's for want of an answer that then reports another id is refused, and left if in use" do
      {:unidentified, p} = Paths.heard(Paths.new(:a, 0, 0), :b, frame(0, 0, 2), 0, 0)
      # b does not answer in time (a host too loaded): given up on, taken for the vehicle's; a falls silent, b is used.
      p = given_up_and_used(Paths.identified(p, :a, 7))

      # Then b's autopilot answers: another one. Refused, and a (heard again) is used.
      {:fresh, p} = Paths.heard(p, :a, frame(20), 19_000, 19_000)
      p = Paths.identified(p, :b, 9)
      assert Paths.uid(p) == 7
      assert {p, [b: {:refused, 9, 7}]} = Paths.settle(p, 19_000, 19_000)
      assert {p, {:b, :a, :another_vehicle}} = Paths.judge(p, 19_000, 19_000)
      assert {:unidentified, _} = Paths.heard(p, :b, frame(2, 0, 2), 19_100, 19_100)
    end

    test "the vehicle's id is that of the autopilot on the path it was discovered on, not of a path taken for it and in use" do
      {:unidentified, p} = Paths.heard(Paths.new(:a, 0, 0), :b, frame(0, 0, 2), 0, 0)
      # Neither answers in time: b given up on, taken for the vehicle's; a falls silent, b is used.
      p = given_up_and_used(p)

      # b, taken for the vehicle's without an answer, is asked on, 8 s apart.
      assert {[:b], p} = Paths.identity_asks(p, 24_000, 24_000)
      assert {[], p} = Paths.identity_asks(p, 31_999, 31_999)

      # b's autopilot answers first: not the vehicle's id. Then a's: b is another vehicle.
      p = Paths.identified(p, :b, 9)
      assert Paths.uid(p) == nil
      {:fresh, p} = Paths.heard(p, :a, frame(20), 32_000, 32_000)
      p = Paths.identified(p, :a, 7)
      assert Paths.uid(p) == 7
      assert {p, [b: {:refused, 9, 7}]} = Paths.settle(p, 32_000, 32_000)
      assert {_, {:b, :a, :another_vehicle}} = Paths.judge(p, 32_000, 32_000)
    end

    test "a new path that answers waits for the vehicle's own id as long as its path in use is heard (a busy autopilot, a lossy link)" do
      {:unidentified, p} = Paths.heard(Paths.new(:a, 0, 0), :b, frame(0, 0, 2), 0, 0)
      p = Paths.identified(p, :b, 9)

      p =
        Enum.reduce(1..60, p, fn s, p ->
          {:fresh, p} = Paths.heard(p, :a, frame(s), s * 1_000, s * 1_000)
          {_asks, p} = Paths.identity_asks(p, s * 1_000, s * 1_000)
          assert {p, []} = Paths.settle(p, s * 1_000, s * 1_000)
          p
        end)

      # A minute later a's autopilot answers: two vehicles.
      assert {_, [b: {:refused, 9, 7}]} = p |> Paths.identified(:a, 7) |> Paths.settle(60_500, 60_500)
    end
  end

  # Path b, pending beside a, asked 5 times without an answer (a heard all
  # along): taken for the vehicle's at 16 s; then a silent and b used at 18 s.
  defp given_up_and_used(p) do
    p =
      Enum.reduce([0, 1_000, 2_000, 4_000, 8_000, 16_000], p, fn t, p ->
        {:fresh, p} = Paths.heard(p, :a, frame(div(t, 1_000)), t, t)
        {_asks, p} = Paths.identity_asks(p, t, t)
        p
      end)

    assert {p, [b: :unidentifiable]} = Paths.settle(p, 16_000, 16_000)
    {:fresh, p} = Paths.heard(p, :b, frame(1, 0, 2), 18_000, 18_000)
    {p, {:a, :b, :silent}} = Paths.judge(p, 18_000, 18_000)
    p
  end
end
