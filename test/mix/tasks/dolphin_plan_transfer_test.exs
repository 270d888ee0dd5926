defmodule Mix.Tasks.Dolphin.PlanTransferTest do
  # `mix dolphin.plan upload` and `download` against simulated vehicles on 127.0.0.1,
  # clean and behind the impairment proxy. Its own Dolphin.Instance (its vehicles,
  # links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.{Mission, Sim}
  alias Dolphin.Test.{GroundStation, UDPProxy, Wait}
  alias Mix.Tasks.Dolphin.Plan

  @moduletag :tmp_dir
  @example Path.expand("../../../examples/single_vehicle.exs", __DIR__)

  setup %{tmp_dir: dir} do
    Dolphin.Test.Instance.on_exit(&GroundStation.forget_vehicles/0)
    plan = Path.join(dir, "survey.plan")
    {:ok, _} = Plan.main(["export", @example, "Survey Area", plan])
    %{plan: plan, port: GroundStation.free_udp_port()}
  end

  defp plan_items(plan), do: plan |> File.read!() |> Mission.from_plan(name: "p") |> elem(1) |> Mission.to_items()

  # Item 0 is home: the simulator keeps its own.
  defp meaning(item), do: {item.command, item.x, item.y, Float.round(item.z * 1.0, 2)}

  test "upload: the vehicle holds exactly the plan's mission, and the report says so", %{plan: plan, port: port} do
    {:ok, [1]} = Sim.start(count: 1, gcs: port, speedup: 5)
    assert {:ok, text} = Plan.main(["upload", plan, "--connect", "udpin:127.0.0.1:#{port}"])
    assert text =~ ~r/^vehicle 1: uploaded \d+ items in \d+\.\d\d s \(\d+ retransmissions?\)/
    assert text =~ "the vehicle holds exactly the mission"

    {:ok, info} = Sim.info(1)
    assert Enum.map(info.mission, &meaning/1) == Enum.map(tl(plan_items(plan)), &meaning/1)
  end

  test "download writes a plan that reads back as the vehicle's mission", %{plan: plan, port: port, tmp_dir: dir} do
    {:ok, [1]} = Sim.start(count: 1, gcs: port, speedup: 5)
    {:ok, _} = Plan.main(["upload", plan, "--connect", "udpin:127.0.0.1:#{port}"])
    out = Path.join(dir, "back.plan")
    assert {:ok, text} = Plan.main(["download", out, "--connect", "udpin:127.0.0.1:#{port}"])
    assert text =~ ~r/^vehicle 1: downloaded \d+ items in \d+\.\d\d s \(\d+ retransmissions?\); wrote #{Regex.escape(out)}$/
    assert Enum.map(tl(plan_items(out)), &meaning/1) == Enum.map(tl(plan_items(plan)), &meaning/1)
  end

  test "upload and download have closed their link's socket when they return: the next one can listen on that port at once", %{plan: plan, port: port, tmp_dir: dir} do
    {:ok, [1]} = Sim.start(count: 1, gcs: port, speedup: 5)

    for argv <- [["upload", plan], ["download", Path.join(dir, "back.plan")]] do
      transfer = Task.async(fn -> Plan.main(argv ++ ["--connect", "udpin:127.0.0.1:#{port}"]) end)
      socket = Wait.until(fn -> link_socket(port) end)
      ref = Port.monitor(socket)
      assert {:ok, _} = Task.await(transfer, 120_000)
      # Closed by the link itself (:normal), not by its process's exit (whose
      # reason it would carry, a moment after main/1 returned).
      assert_receive {:DOWN, ^ref, :port, ^socket, :normal}, 30_000
      assert {:ok, listening} = :gen_udp.open(port, ip: {127, 0, 0, 1})
      :gen_udp.close(listening)
    end
  end

  # The socket of the link that listens on `port`, once there is one.
  defp link_socket(port) do
    Enum.find_value(DynamicSupervisor.which_children(Dolphin.Instance.names().links), fn {_, link, _, _} ->
      with {:links, linked} <- Process.info(link, :links),
           do: Enum.find(linked, &(is_port(&1) and :inet.port(&1) == {:ok, port}))
    end)
  end

  test "over 30 % loss each way, 10 % duplicates and reordering the upload is still exact", %{plan: plan, port: port} do
    proxy = start_supervised!({UDPProxy, gcs: port, seed: 9, both: [loss: 0.3, duplicate: 0.1, reorder: 0.1]})
    {:ok, [1]} = Sim.start(count: 1, gcs: UDPProxy.port(proxy), speedup: 5)
    assert {:ok, text} = Plan.main(["upload", plan, "--connect", "udpin:127.0.0.1:#{port}", "--timeout", "20"])
    assert text =~ "the vehicle holds exactly the mission"
    assert UDPProxy.stats(proxy).to_vehicle.dropped > 0
  end

  test "which vehicle: --vehicle, or a clear error naming those heard", %{plan: plan, port: port} do
    {:ok, [1, 2]} = Sim.start(count: 2, gcs: port, speedup: 5)
    why = message(Plan.main(["upload", plan, "--connect", "udpin:127.0.0.1:#{port}"]))
    assert why == "vehicles 1, 2 are on udpin:127.0.0.1:#{port}: say which with --vehicle ID"
    assert {:ok, "vehicle 2: uploaded" <> _} = Plan.main(["upload", plan, "--connect", "udpin:127.0.0.1:#{port}", "--vehicle", "2"])
    # (Vehicles 1 and 2 are heard anew by the command's own link: within 5 s on a loaded host.)
    why = message(Plan.main(["download", "x.plan", "--connect", "udpin:127.0.0.1:#{port}", "--vehicle", "7", "--timeout", "5"]))
    assert why == "no vehicle 7 heard on udpin:127.0.0.1:#{port} (heard: 1, 2)"
  end

  test "no vehicle, a refusal, bad usage: clear errors", %{plan: plan, port: port, tmp_dir: dir} do
    why = message(Plan.main(["upload", plan, "--connect", "udpin:127.0.0.1:#{port}", "--timeout", "1"]))
    assert why =~ "no vehicle heard on udpin:127.0.0.1:#{port}"

    # More items than the simulated ArduCopter takes (650).
    long = Path.join(dir, "long.plan")
    items = [hd(plan_items(plan)) | for(i <- 1..700, do: %{Enum.at(plan_items(plan), 1) | x: 404_442_330 + i * 10, command: 16, frame: 6})]
    {:ok, mission} = Dolphin.Console.MissionSource.from_items(items, "long")
    File.write!(long, Mission.to_plan(mission))
    {:ok, [1]} = Sim.start(count: 1, gcs: port, speedup: 5)
    why = message(Plan.main(["upload", long, "--connect", "udpin:127.0.0.1:#{port}"]))
    assert why =~ ~r/^upload failed after \d+\.\d\d s \(\d+ retransmissions?\): vehicle 1 refused the mission upload: MAV_MISSION_NO_SPACE/

    why = message(Plan.main(["upload", plan]))
    assert why =~ "--connect ENDPOINT is needed"
    why = message(Plan.main(["upload", plan, "--connect", "carrier-pigeon:1"]))
    assert why =~ "--connect carrier-pigeon:1"
  end

  defp message(result) do
    assert {:error, %Dolphin.CommandLineError{} = e} = result
    Exception.message(e)
  end
end
