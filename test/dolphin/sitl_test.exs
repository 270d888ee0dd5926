defmodule Dolphin.SITLTest do
  # ArduCopter SITL as a backend, and what the ground station does with the
  # real autopilot: its mission protocol, arming before the position estimate
  # is ready, a stop that holds position, a vehicle that vanishes, a lossy link.
  # Runs ArduCopter processes and changes the clock's speed-up: not async.
  use ExUnit.Case, async: false

  alias Dolphin.{Clock, Engine, Geo, Mission, SITL, Vehicles}
  alias Dolphin.Mission.Command, as: C
  alias Dolphin.Test.{Backend, UDPProxy, Wait}

  @moduletag :sitl
  @moduletag timeout: 300_000

  setup do
    Dolphin.Fleet.set_source({Dolphin.Fleet.MAVLinkSource, nil})
    :ok
  end

  defp pick(id), do: {:ok, _} = Dolphin.Fleet.pick(Dolphin.Fleet, self(), id: id)

  defp hop(home) do
    Mission.new("hop")
    |> Mission.add(C.home(home))
    |> Mission.add(C.take_off(%{home | h: home.h + 10}))
    |> Mission.add(C.move(20, 0, 0))
    |> Mission.add(C.return_home_and_land())
  end

  # A stand-in for the SITL binary in `dir` (with its defaults file beside
  # it), running the shell commands `body`.
  defp fake_binary(dir, body) do
    fake = Path.join(dir, "arducopter")
    File.write!(fake, "#!/bin/sh\n" <> body <> "\n")
    File.chmod!(fake, 0o755)
    File.write!(Path.join(dir, "copter.parm"), "")
    fake
  end

  # What SITL sends to instead of the ground station's port: a proxy in
  # between (its faults `opts`), announced to `test` as {:proxy, pid}.
  defp behind_proxy(test, opts) do
    fn gcs_port ->
      {:ok, proxy} = UDPProxy.start_link([gcs: gcs_port] ++ opts)
      send(test, {:proxy, proxy})
      UDPProxy.port(proxy)
    end
  end

  describe "Dolphin.SITL" do
    test "a missing binary or defaults file is a clear error" do
      assert {:error, %SITL.Error{} = e} = SITL.start(1, bin: "/nonexistent/arducopter")
      message = Exception.message(e)
      assert message =~ "no ArduCopter SITL binary at /nonexistent/arducopter (--sitl-bin)"

      {:ok, bin} = SITL.find_binary()
      assert {:error, %SITL.Error{} = e} = SITL.start(1, bin: bin, defaults: ["/nonexistent/x.parm"])
      message = Exception.message(e)
      assert message =~ "no such defaults file: /nonexistent/x.parm"
    end

    # Its exit is logged with the lines it printed: expected here.
    @tag :tmp_dir
    @tag :capture_log
    test "a binary that exits at once is reported with the last lines it printed", %{tmp_dir: dir} do
      fake = fake_binary(dir, "echo 'bad option --model'\necho 'giving up'\nexit 3")
      assert {:error, %SITL.Error{} = e} = SITL.start(1, bin: fake)
      message = Exception.message(e)
      assert message =~ "exited with status 3 before it answered"
      assert message =~ "giving up"
    end

    # The lock files of instance numbers in a directory of the test's own,
    # so that SITL runs elsewhere on the machine do not change the answer.
    @tag :tmp_dir
    @tag :capture_log
    test "instance numbers are free on the machine: one held by a live process is skipped, a stale one taken over", %{tmp_dir: dir} do
      fake = fake_binary(dir, "echo \"args: $*\"\nexit 3")
      locks = Path.join(dir, "locks")
      File.mkdir_p!(locks)
      lock = &Path.join(locks, "dolphin-sitl-instance-#{&1}.lock")
      # 0: another ground station running now (this very OS process will do); 1: one that crashed.
      File.write!(lock.(0), System.pid())
      File.write!(lock.(1), "999999999")
      Application.put_env(:dolphin, :sitl_lock_dir, locks)
      on_exit(fn -> Application.delete_env(:dolphin, :sitl_lock_dir) end)

      assert {:error, %SITL.Error{} = e} = SITL.start(1, bin: fake)
      assert Exception.message(e) =~ ~r/args: .*-I 1 /
      # Released with the failed start; the live one's untouched.
      refute File.exists?(lock.(1))
      assert File.read!(lock.(0)) == System.pid()
    end

    test "instances get distinct system ids, homes 30 m apart, and stop cleanly" do
      ids = Backend.start(:sitl, 2)
      assert ids == [1, 2]
      [a, b] = Enum.map(ids, &Backend.home/1)
      assert_in_delta Geo.distance(a, b), 30, 1
      # This fleet's own processes: other SITL runs may share the machine.
      os_pids = for instance <- Backend.fleet(1).instances, do: :sys.get_state(instance).os_pid
      Backend.stop(ids)
      assert Vehicles.list() == []
      Wait.until(fn -> not Enum.any?(os_pids, &File.dir?("/proc/#{&1}")) end, 250, fn -> "SITL processes #{inspect(os_pids)} gone" end)
    end
  end

  test "two ArduCopters with one system id on two links: the second is another vehicle by its unique id, and each is commanded apart" do
    Clock.set_speedup(Backend.speedup(:sitl))
    Dolphin.Events.subscribe()
    Vehicles.subscribe(:all)
    {:ok, first} = SITL.start(1, first_sysid: 7)
    # Its fleet is ready at once (vehicle 7 is): its autopilot is heard when it has booted.
    {:ok, second} = SITL.start(1, first_sysid: 7)

    try do
      assert_receive {:dolphin, :events, %{event: :system_id_shared, vehicle: 7, uid: other, vehicle_uid: own, other: name}}, 60_000
      # ArduPilot's SITL reports a unique id of its own per instance, as a board its serial number.
      assert other > 0 and own > 0 and other != own
      assert "7@" <> _ = name
      assert [%{in_use?: true, identity: :same, uid: ^own}, %{identity: :refused, uid: ^other}] = Vehicles.paths(7)
      assert {:ok, %{uid: ^own}} = Vehicles.view(7)

      # The second is a vehicle of its own, and commands reach the right one.
      assert_receive {:dolphin, :vehicles, {:vehicle_discovered, ^name}}, 60_000
      Wait.until(fn -> match?({:ok, %{uid: ^other}}, Vehicles.view(name)) end, 500, fn -> "#{name}'s unique id" end)
      # Booted through (a mode set before ArduCopter reads its RC mode switch
      # at start-up is replaced by the switch's): its EKF uses GPS.
      for id <- [7, name] do
        Wait.until(fn -> match?({:ok, %{status_texts: texts}} when is_list(texts), Vehicles.view(id)) and Enum.any?(elem(Vehicles.view(id), 1).status_texts, fn {_, t} -> t =~ "is using GPS" end) end, 3_000, fn -> "vehicle #{id} using GPS" end)
      end

      assert {:ok, :accepted} = Vehicles.set_mode(name, :alt_hold)
      assert {:ok, :accepted} = Vehicles.set_mode(7, :acro)
      Wait.until(fn -> match?({:ok, %{mode: :alt_hold}}, Vehicles.view(name)) and match?({:ok, %{mode: :acro}}, Vehicles.view(7)) end, 3_000, fn ->
        "7 in ACRO and #{name} in ALT_HOLD: #{inspect(for id <- [7, name], do: Vehicles.view(id) |> elem(1) |> Map.take([:mode, :network, :status_texts]))}"
      end)
    after
      SITL.stop(second)
      SITL.stop(first)
      for id <- Vehicles.list(), is_binary(id), do: Vehicles.forget(id)
      Clock.set_speedup(1)
    end
  end

  test "the SITL fleet charges a landed vehicle: MAV_CMD_BATTERY_RESET sets the charge, which then rises" do
    [id] = Backend.start(:sitl, 1)
    Wait.until(fn -> match?({:ok, %{battery: b}} when is_number(b), Vehicles.state(id)) end, 500)
    assert {:ok, :accepted} = Vehicles.command(id, :mav_cmd_battery_reset, [1, 40.0])
    Wait.until(fn -> match?({:ok, %{battery: b}} when b < 0.45, Vehicles.state(id)) end, 500)
    # 0.5 % a second of clock time: 10 s make 5 %.
    Clock.sleep(12_000)
    assert {:ok, %{battery: b}} = Vehicles.state(id)
    assert b >= 0.43 and b <= 0.5
  end

  test "mission protocol on ArduCopter: 650 items exact both ways, 700 refused with its reason, clear, a bad item refused" do
    [id] = Backend.start(:sitl, 1)
    home = Backend.home(id)
    many = fn n -> Enum.reduce(1..(n - 3), hop(home) |> Map.update!(:commands, &Enum.take(&1, 2)), fn i, m -> Mission.add(m, C.move(rem(i, 7) - 3, rem(i, 5) - 2, 0)) end) end

    # ArduCopter SITL stores 650 items (home included): the most it takes.
    items = Mission.to_items(many.(650))
    assert length(items) == 650
    assert :ok = Vehicles.upload_mission(id, items), inspect(Vehicles.state(id))
    assert {:ok, back} = Vehicles.download_mission(id)
    assert :ok = Mission.compare_download(items, back)

    assert {:error, %Dolphin.MissionError{result: :no_space}} = Vehicles.upload_mission(id, Mission.to_items(many.(700)))
    Wait.until(fn -> match?({:ok, %{status_texts: [{_, "Only 650 items are supported"} | _]}}, Vehicles.state(id)) end)

    assert :ok = Vehicles.clear_mission(id)
    # Cleared, ArduCopter reports a count of 0: not even home is read back.
    assert {:ok, []} = Vehicles.download_mission(id)

    # A take-off whose pitch is not a number: ArduCopter refuses the item.
    [h, t | _] = Mission.to_items(hop(home))
    assert {:error, %Dolphin.MissionError{result: result}} = Vehicles.upload_mission(id, [h, %{t | param4: 0.0, command: 31_999}])
    assert result in [:unsupported, :invalid_param4, :invalid]
  end

  test "Table 2 on ArduCopter: the commands the other SITL tests do not fly, each reached in order at its point" do
    [id] = Backend.start(:sitl, 1)
    home = Backend.home(id)
    pick(id)
    up = home.h + 20

    # Item numbers: 1 take-off, 2 go_pos, 3 move_from_home, 4 loiter_turns,
    # 5 loiter_time, 6 move_and_loiter_time_from_home, 7 jump back to 5 once,
    # 8 return_home_and_loiter (endless: the task is stopped there).
    mission =
      Mission.new("table 2")
      |> Mission.add(C.home(home))
      |> Mission.add(C.take_off_with_yaw(%{home | h: up}, 15, 90))
      |> Mission.add(C.go_pos(%{Geo.offset(home, 30, 0) | h: up}))
      |> Mission.add(C.move_from_home(30, 30, 20))
      |> Mission.add(C.loiter_turns(%{Geo.offset(home, 0, 30) | h: up}, 1, 8))
      |> Mission.add(C.loiter_time(%{Geo.offset(home, -20, 20) | h: up}, 3))
      |> Mission.add(C.move_and_loiter_time_from_home(-20, -20, 20, 2))
      |> Mission.add(C.jump_to_item(5, 1))
      |> Mission.add(C.return_home_and_loiter())

    items = Mission.to_items(mission)
    Vehicles.subscribe(id)
    at_end = fn -> match?({:ok, %{mission: %{current: 8}, mode: :auto}}, Vehicles.state(id)) end
    assert {:ok, :done} = Engine.run(Engine.on(Engine.until(mission, at_end), [id]))

    # Where the vehicle was when each item was reported reached.
    reached = reached_positions(id)
    # The jump sends the vehicle back to 5 once (DO_JUMP itself is never
    # reported reached).
    assert Enum.map(reached, &elem(&1, 0)) == [1, 2, 3, 4, 5, 6, 5, 6]

    for {seq, at} <- reached, item = Enum.at(items, seq), item.command in [16, 19] do
      point = Geo.location(item.x / 1.0e7, item.y / 1.0e7)
      # Positions come a few times a second: within 5 m of the point.
      assert Geo.distance(point, at) < 5, "item #{seq} reached #{Geo.distance(point, at)} m from its point"
    end
  end

  # {seq, location} for each MISSION_ITEM_REACHED reported, from the views received.
  defp reached_positions(id, acc \\ [], last \\ nil) do
    receive do
      {:dolphin, {:vehicle, ^id}, {:view, view}} ->
        last = if view.position, do: Geo.location(view.position.lat, view.position.lon), else: last

        case view.mission do
          %{reached: seq} when seq != nil and (acc == [] or elem(hd(acc), 0) != seq) -> reached_positions(id, [{seq, last} | acc], last)
          _ -> reached_positions(id, acc, last)
        end
    after
      0 -> Enum.reverse(acc)
    end
  end

  test "arming refused before the position estimate is ready is retried; the mission then flies and lands" do
    [id] = Backend.start(:sitl, 1)
    home = Backend.home(id)
    pick(id)
    # At once after boot: ArduCopter refuses to arm until its EKF uses GPS.
    assert {:ok, :done} = Engine.run(Engine.on(hop(home), [id]))
    {:ok, st} = Vehicles.state(id)
    refute st.armed
    texts = Enum.map(st.status_texts, &elem(&1, 1))
    assert "Arming motors" in texts
    assert Enum.any?(texts, &(&1 =~ "Need Position Estimate"))
  end

  test "a stopped mission leaves the vehicle holding its position and height for 30 s" do
    [id] = Backend.start(:sitl, 1)
    home = Backend.home(id)
    pick(id)

    endless = Mission.new("endless") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 15})) |> Mission.add(C.move_and_loiter_pos(40, 0, 0, 10))
    at_loiter = fn -> match?({:ok, %{mission: %{current: 2}, mode: :auto}}, Vehicles.state(id)) end
    assert {:ok, :done} = Engine.run(Engine.on(Engine.until(endless, at_loiter), [id]))

    # BRAKE stops with a short overshoot, then holds.
    Wait.until(fn -> match?({:ok, %{mode: :brake, armed: true}}, Vehicles.state(id)) end, 500)
    Clock.sleep(5_000)
    {:ok, %{position: a}} = Vehicles.state(id)
    samples = for _ <- 1..6, do: (Clock.sleep(5_000); Vehicles.state(id))

    for {:ok, st} <- samples do
      assert st.mode == :brake and st.armed
      assert Geo.distance(Geo.location(a.lat, a.lon), Geo.location(st.position.lat, st.position.lon)) < 3
      assert_in_delta st.position.relative_alt, 15, 1.5
    end

    assert {:ok, :done} = Engine.run(Engine.on(hop(home), [id]))
  end

  # At 2x the motors' spool-up (3 s of clock) lasts 1.5 s of real time:
  # the hold, sent the moment MISSION_START is accepted, comes within it.
  test "held on the ground during its take-off's spool-up, ArduCopter disarms itself; let go, the mission arms, starts again and flies" do
    [id] = Backend.start(:sitl, 1, speedup: 2)
    home = Backend.home(id)
    pick(id)
    Dolphin.Events.subscribe()
    {:ok, pid} = Dolphin.Mission.Executor.start_link(hop(home), id, [owner: self()] ++ Dolphin.Test.SeparationHold.at_first_flight())

    # BRAKE holds nothing on the ground: DISARM_DELAY (10 s) after it, ArduCopter disarms.
    Wait.until(fn -> match?({:ok, %{mode: :brake, armed: false}}, Vehicles.state(id)) end, div(Clock.to_real_ms(180_000), 20), fn -> "vehicle #{id} disarmed in BRAKE: #{inspect(Vehicles.view(id))}" end)
    {:ok, st} = Vehicles.state(id)
    assert st.landed == :on_ground and st.position.relative_alt < 1
    assert "Disarming motors" in Enum.map(st.status_texts, &elem(&1, 1))
    # A few more views: the mission waits.
    Clock.sleep(3_000)
    assert {:flying, _} = :sys.get_state(pid)

    Dolphin.Test.SeparationHold.let_go(pid)
    assert_receive {:dolphin_platform, ^pid, :done}, Clock.to_real_ms(240_000)
    assert_received {:dolphin, :events, %{event: :mission_restarted, vehicle: ^id, reason: :disarmed_while_held}}
    {:ok, st} = Vehicles.state(id)
    refute st.armed
    assert Geo.distance(Geo.location(st.position.lat, st.position.lon), home) < 5
  end

  # The killed instance's exit is logged: expected here.
  @tag :capture_log
  test "a vehicle that vanishes mid-mission is lost within the connection timeout; its task fails and the watch handler runs" do
    [id] = Backend.start(:sitl, 1)
    home = Backend.home(id)
    pick(id)
    Vehicles.set_timeout(id, 5_000)
    test = self()
    handler = fn failure -> send(test, {:handled, failure}) end
    long = Mission.new("long") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 10})) |> Mission.add(C.move_and_loiter_time(200, 0, 0, 600))

    {:ok, run} = Engine.start(Engine.watch(Engine.on(long, [id]), on_error: handler))
    Wait.until(fn -> match?({:ok, %{armed: true, position: %{relative_alt: alt}}} when alt > 3, Vehicles.state(id)) end, 3_000)
    Vehicles.subscribe(:all)
    lost_from = Clock.now_ms()
    :ok = SITL.crash(Backend.fleet(id), id)

    assert_receive {:dolphin, :vehicles, {:vehicle_lost, ^id}}, Clock.to_real_ms(30_000) + 2_000
    # Lost after its 5 s of silence, with the slack of the link's checks: the
    # timeout set, not the default one (at 10x never under 5 s of real time,
    # 50 s of clock). A check that runs late does not judge (a busy host), and
    # beside two busy loops and fleets flying in the suite's other BEAM a loss
    # was judged 18 s of clock (1.8 s of real time) after the crash.
    assert Clock.now_ms() - lost_from < 25_000
    assert_receive {:handled, %Dolphin.Engine.Failure{vehicle: ^id, reason: {:vehicle_lost, ^id}}}, 10_000
    assert {:ok, :done} = Engine.await(run, 30_000)
  end

  test "over a link that loses 20 % each way, duplicates and reorders, a mission uploads exactly and flies" do
    test = self()

    send_to = behind_proxy(test, seed: 7, both: [loss: 0.2, duplicate: 0.05, reorder: 0.05])

    [id] = Backend.start(:sitl, 1, send_to: send_to)
    assert_received {:proxy, proxy}
    home = Backend.home(id)
    pick(id)
    Dolphin.Events.subscribe()

    assert {:ok, :done} = Engine.run(Engine.on(hop(home), [id]))
    assert_received {:dolphin, :events, %{event: :mission_uploaded, vehicle: ^id, items: 4}}
    assert %{to_gcs: %{dropped: lost}} = UDPProxy.stats(proxy)
    assert lost > 0
  end

  # The real autopilot's mission protocol behind a bad radio link: 100-item
  # missions go up and come back exactly, every time, with both uploaders.
  test "over 30 % loss each way, 10 % duplicates and 10 % reordering, 100-item uploads and their read-backs are exact" do
    test = self()

    send_to = behind_proxy(test, seed: 3)

    [id] = Backend.start(:sitl, 1, send_to: send_to, speedup: 5)
    assert_received {:proxy, proxy}
    home = Backend.home(id)
    :ok = UDPProxy.set(proxy, both: [loss: 0.3, duplicate: 0.1, reorder: 0.1])

    for {round, ahead?} <- [{1, true}, {2, true}, {3, false}] do
      mission = Mission.new("long #{round}") |> Mission.add(C.home(home)) |> Mission.add(C.take_off(%{home | h: home.h + 10}))
      mission = Enum.reduce(1..98, mission, fn i, m -> Mission.add(m, C.move(rem(i, 7) * 5.0 + round, rem(i, 5) * 5.0, 0)) end)
      items = Mission.to_items(mission)
      assert length(items) == 100

      upload = Vehicles.upload_mission(id, items, send_ahead: ahead?)
      assert upload == :ok or match?({:error, %Dolphin.MissionError{result: :unconfirmed}}, upload), "round #{round}: #{inspect(upload)}"
      assert {:ok, back} = Vehicles.download_mission(id)
      assert :ok = Mission.compare_download(items, back), "round #{round}"
    end

    assert %{to_gcs: %{dropped: a}, to_vehicle: %{dropped: b}} = UDPProxy.stats(proxy)
    assert a > 100 and b > 100
  end

  # The parameter micro-service on the real autopilot, behind the same bad
  # radio link: ArduCopter's whole list (over a thousand), each index once
  # and exactly as read one by one; a set read back; a value it keeps
  # otherwise refused; a name it does not have said with the names near.
  test "parameters on ArduCopter over 30 % loss each way: the whole list exact, typed; set, refused, unknown" do
    test = self()

    send_to = behind_proxy(test, seed: 5)

    [id] = Backend.start(:sitl, 1, send_to: send_to, speedup: 5)
    assert_received {:proxy, proxy}
    # Once it has its home (ArduCopter counts it in MIS_TOTAL then).
    _ = Backend.home(id)
    # Clean first: the reference list.
    assert {:ok, clean} = Vehicles.param_list(id)
    assert length(clean) > 1000
    assert Enum.map(clean, & &1.index) == Enum.to_list(0..(length(clean) - 1))

    :ok = UDPProxy.set(proxy, both: [loss: 0.3, duplicate: 0.1, reorder: 0.1])
    lossy = with({:ok, lossy} <- Vehicles.param_list(id), do: lossy, else: (error -> flunk("the list over the lossy link: #{inspect(error)}")))
    assert Enum.map(lossy, & &1.name) == Enum.map(clean, & &1.name)
    # The same values, but those ArduPilot counts itself as it runs (STAT_RUNTIME, ...).
    differ = for {a, b} <- Enum.zip(clean, lossy), a.value != b.value, not String.starts_with?(a.name, "STAT_"), do: {a.name, a.value, b.value}
    assert differ == []

    # Typed as ArduPilot says: FENCE_ACTION is an INT8, WPNAV_SPEED a REAL32.
    assert %{type: 2, value: action} = Enum.find(clean, &(&1.name == "FENCE_ACTION"))
    assert {:ok, ^action} = Vehicles.param(id, "FENCE_ACTION", nil, [])
    assert {:ok, 750.0} = Vehicles.param(id, "WPNAV_SPEED", 750, [])
    assert {:ok, 750.0} = Vehicles.param(id, "WPNAV_SPEED", nil, [])

    # An INT8 keeps a whole number: ArduCopter answers with the one it kept.
    assert {:error, %Dolphin.ParamError{result: :refused, kept: kept}} = Vehicles.param(id, "FENCE_ACTION", 2.5, [])
    assert kept in [2.0, 3.0]
    assert {:error, %Dolphin.ParamError{result: :unknown} = e} = Vehicles.param(id, "WPNAV_SPEEED", nil, attempts: 3)
    assert Exception.message(e) =~ "has no parameter WPNAV_SPEEED (did you mean WPNAV_SPEED"
  end
end
