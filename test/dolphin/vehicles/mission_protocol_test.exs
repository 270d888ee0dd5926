defmodule Dolphin.Vehicles.MissionProtocolTest do
  # The ground station's mission protocol against a scripted ArduCopter-like
  # vehicle (test/support/scripted_vehicle.ex) over UDP on 127.0.0.1, clean and
  # lossy. Changes the clock speed-up: not async.
  use ExUnit.Case, async: false

  alias Dolphin.Test.Wait

  import Dolphin.Property

  alias :proper_types, as: T
  alias Dolphin.{Clock, Link, MissionError, Vehicles}
  alias Dolphin.Link.Connection
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Test.ScriptedVehicle

  doctest Dolphin.MissionError

  # Over a clean link nothing is retried, and nothing should time out however
  # slowly a loaded machine runs both sides: real time. The vehicle that stops
  # answering is given up on faster, and the lossy property runs faster still
  # (see there).
  @speedup 1
  @silent_speedup 20
  @lossy_speedup 100

  setup do
    name = "mission-#{System.unique_integer([:positive])}"
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: name)
    Clock.set_speedup(@speedup)

    on_exit(fn ->
      Clock.set_speedup(1)
      DynamicSupervisor.terminate_child(Dolphin.Link.Supervisor, link)
    end)

    %{port: Connection.port(name), link: name}
  end

  defp vehicle(port, opts) do
    sysid = 30 + rem(System.unique_integer([:positive]), 200)
    {:ok, pid} = ScriptedVehicle.start_link([port: port, sysid: sysid, speedup: Dolphin.Clock.speedup()] ++ opts)
    Wait.until(fn -> Vehicles.whereis(sysid) end)

    on_exit(fn ->
      if v = Vehicles.whereis(sysid), do: DynamicSupervisor.terminate_child(Dolphin.Vehicles.Supervisor, v)
    end)

    {sysid, pid}
  end

  defp items(n) do
    for i <- 0..(n - 1)//1 do
      %M.MissionItemInt{frame: 6, command: 16, autocontinue: 1, param4: :nan, x: 411_780_000 + i * 100, y: -85_960_000 - i, z: 20.0 + i}
    end
  end

  # What the vehicle holds, compared with what was uploaded.
  defp same_mission?(held, uploaded) do
    length(held) == length(uploaded) and
      Enum.all?(Enum.zip(held, uploaded), fn {h, u} -> meaning(h) == meaning(u) end)
  end

  # An item without what only addresses it (targets, position in the list).
  defp meaning(item), do: %{item | seq: 0, mission_type: 0, target_system: 0, target_component: 0}


  # The vehicle's mission state as published, once it satisfies `fun`.
  defp await_mission(sysid, fun) do
    receive do
      {:dolphin, {:vehicle, ^sysid}, {:state, ^sysid, changes}} ->
        case Keyword.fetch(changes, :mission) do
          {:ok, mission} -> if fun.(mission), do: mission, else: await_mission(sysid, fun)
          :error -> await_mission(sysid, fun)
        end
    after
      Clock.to_real_ms(30_000) -> flunk("vehicle #{sysid}: no mission state as expected")
    end
  end

  defp reached(sysid, link, seq),
    do: Vehicles.route(%Dolphin.MAVLink.Frame{sysid: sysid, compid: 1, seq: 0, message: %M.MissionItemReached{seq: seq}}, link)

  test "an upload or a clear makes the vehicle forget the previous mission's progress, and say so", %{port: port, link: link} do
    {sysid, _vehicle} = vehicle(port, [])
    Vehicles.subscribe(sysid)

    reached(sysid, link, 2)
    await_mission(sysid, &(&1.reached == 2))
    assert :ok = Vehicles.upload_mission(sysid, items(3))
    assert %{reached: nil, total: nil} = await_mission(sysid, &(&1.reached == nil))
    assert {:ok, %{mission: %{reached: nil}}} = Vehicles.state(sysid)

    # The new mission reaching its item 2 is news, not "no change".
    reached(sysid, link, 2)
    await_mission(sysid, &(&1.reached == 2))
    assert :ok = Vehicles.clear_mission(sysid)
    await_mission(sysid, &(&1.reached == nil))
    assert {:ok, %{mission: %{reached: nil}}} = Vehicles.state(sysid)

    # A download leaves the mission as it is.
    reached(sysid, link, 1)
    await_mission(sysid, &(&1.reached == 1))
    assert {:ok, _} = Vehicles.download_mission(sysid)
    assert {:ok, %{mission: %{reached: 1}}} = Vehicles.state(sysid)
  end

  test "upload, download and clear over a clean link, with progress", %{port: port} do
    {sysid, vehicle} = vehicle(port, [])
    mission = items(6)
    assert :ok = Vehicles.upload_mission(sysid, mission, progress_to: self())
    for i <- 1..6, do: assert_received({:mission_progress, :upload, ^i, 6})
    assert same_mission?(ScriptedVehicle.mission(vehicle), mission)

    assert {:ok, downloaded} = Vehicles.download_mission(sysid)
    assert Enum.map(downloaded, & &1.seq) == Enum.to_list(0..5)
    assert same_mission?(downloaded, mission)

    assert :ok = Vehicles.clear_mission(sysid)
    assert {:ok, []} = Vehicles.download_mission(sysid)
  end

  test "fence and rally lists are their own lists", %{port: port} do
    {sysid, vehicle} = vehicle(port, [])
    fence = for i <- 0..3, do: %M.MissionItemInt{frame: 5, command: 5001, param1: 4.0, x: 411_780_000 + i * 1000, y: -85_960_000}
    rally = [%M.MissionItemInt{frame: 6, command: 5100, x: 411_790_000, y: -85_950_000, z: 15.0}]

    assert :ok = Vehicles.upload_mission(sysid, items(3))
    assert :ok = Vehicles.upload_mission(sysid, fence, mission_type: :fence)
    assert :ok = Vehicles.upload_mission(sysid, rally, mission_type: :rally)
    assert same_mission?(ScriptedVehicle.mission(vehicle, 1), fence)
    assert same_mission?(ScriptedVehicle.mission(vehicle, 2), rally)
    assert length(ScriptedVehicle.mission(vehicle, 0)) == 3

    assert {:ok, got} = Vehicles.download_mission(sysid, mission_type: :fence)
    assert same_mission?(got, fence) and Enum.all?(got, &(&1.mission_type == 1))
    assert :ok = Vehicles.clear_mission(sysid, mission_type: :rally)
    assert ScriptedVehicle.mission(vehicle, 2) == [] and length(ScriptedVehicle.mission(vehicle, 0)) == 3
  end

  test "a refusal is a clear error; a second transfer waits for the first", %{port: port} do
    {sysid, _vehicle} = vehicle(port, limit: 10)
    assert {:error, %MissionError{result: :no_space} = e} = Vehicles.upload_mission(sysid, items(11))
    assert Exception.message(e) == "vehicle #{sysid} refused the mission upload: MAV_MISSION_NO_SPACE"

    # Both requests from this process, so the vehicle gets them in this order
    # (what Vehicles.upload_mission/3 and download_mission/2 send): the
    # download must wait for the upload to end.
    pid = Vehicles.whereis(sysid)
    upload = %{operation: :upload, items: items(8), mission_type: :mission, progress_to: nil}
    r1 = :gen_server.send_request(pid, {:mission, upload, []})
    r2 = :gen_server.send_request(pid, {:mission, %{operation: :download, mission_type: :mission, progress_to: nil}, []})
    assert {:reply, :ok} = :gen_server.wait_response(r1, 60_000)
    assert {:reply, {:ok, got}} = :gen_server.wait_response(r2, 60_000)
    assert length(got) == 8
  end

  test "a vehicle that stops answering: a timeout error within the time limit", %{port: port} do
    Clock.set_speedup(@silent_speedup)
    {sysid, vehicle} = vehicle(port, [])
    ScriptedVehicle.set_faults(vehicle, loss: 1.0)
    assert {:error, %MissionError{result: :timeout, operation: :download}} = Vehicles.download_mission(sysid, attempts: 3)
    assert {:error, %MissionError{result: :timeout, operation: :upload}} = Vehicles.upload_mission(sysid, items(3), attempts: 3)
  end

  # Random missions over a link that drops, duplicates and reorders frames both
  # ways: the upload either leaves the vehicle with exactly that mission and
  # says :ok, or says why not; it never says :ok for anything else.
  @tag timeout: 300_000
  test "lossy link: an accepted upload is exactly the mission, or a clear error", %{port: port} do
    # Many retries: the vehicle re-asks every 10 ms of real time (8 times before
    # it gives up), our retries wait 20 ms at least (Clock.retry_real_ms/2: a
    # round trip does not speed up). A pause of the machine only adds errors,
    # which the property allows; that uploads do get through faults is checked
    # after it, in real time.
    Clock.set_speedup(@lossy_speedup)
    {sysid, vehicle} = vehicle(port, [])

    check(
      forall({T.integer(1, 700), T.integer(0, 40), T.integer(0, 20), T.integer(0, 20)}, fn {n, loss, dup, reorder} ->
        ScriptedVehicle.set_faults(vehicle, loss: loss / 100, duplicate: dup / 100, reorder: reorder / 100)
        mission = items(n)

        case Vehicles.upload_mission(sysid, mission, attempts: 8) do
          :ok ->
            assert same_mission?(ScriptedVehicle.mission(vehicle), mission), "accepted, but the vehicle holds another mission"

          {:error, %MissionError{result: result}} -> assert result in [:timeout, :operation_cancelled]
        end

        ScriptedVehicle.set_faults(vehicle, [])
        true
      end),
      numtests: 12
    )

    # The property is not won by failing: in real time, where no pause of a
    # loaded machine outlasts the vehicle's 8 s of patience, an upload through
    # every kind of fault succeeds.
    Clock.set_speedup(@speedup)
    {sysid, vehicle} = vehicle(port, loss: 0.1, duplicate: 0.1, reorder: 0.1)
    assert :ok = Vehicles.upload_mission(sysid, items(30), attempts: 8)
    assert same_mission?(ScriptedVehicle.mission(vehicle), items(30))

    # And on a clean link it always works.
    ScriptedVehicle.set_faults(vehicle, [])
    assert :ok = Vehicles.upload_mission(sysid, items(700))
    assert length(ScriptedVehicle.mission(vehicle)) == 700
  end

end
