defmodule Dolphin.Test.UDPProxySimTest do
  # A simulated ArduCopter behind the impairment proxy (as SITL would be), and the
  # ground station's mission protocol through it: up to 30 % loss each way, 10 %
  # duplicates, 10 % reordering, a different mix for every seed. Its own
  # Dolphin.Instance (its vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.{Sim, Vehicles}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Test.{UDPProxy, Wait}

  # Retries of 1 s of clock time become 100 ms: room for the proxy's holds
  # (20 ms) and a loaded machine's pauses.
  @speedup 10
  # One transfer can pass by luck: a dozen seeds (a dozen different runs of
  # faults) make a defect that strikes one transfer in five show.
  @seeds 1..12

  setup do
    %{gcs_port: Dolphin.Test.GroundStation.open()}
  end

  defp items(n) do
    home = %M.MissionItemInt{seq: 0, frame: 0, command: 16, x: 404_442_330, y: -73_752_340, z: 0.0}

    [home | for(i <- 1..n, do: %M.MissionItemInt{seq: i, frame: 6, command: 16, autocontinue: 1, param1: i * 1.0, x: 404_442_330 + i * 100, y: -73_752_340 - i * 10, z: 20.0 + i})]
  end

  # Item 0 is home: the vehicle ignores an uploaded one and hands out its own.
  defp meaning(item), do: {item.seq, item.command, item.x, item.y, item.z, item.param1, item.autocontinue}

  # One upload and download through a fresh proxy seeded with `seed`: nil when
  # both are exact, else what went wrong.
  defp transfer(gcs_port, seed, uploaded) do
    :rand.seed(:exsss, {seed, 14, 15})
    faults = [loss: :rand.uniform(31) - 1, duplicate: :rand.uniform(11) - 1, reorder: :rand.uniform(11) - 1]
    # Vehicle 1 must be the one behind this proxy, not one heard before it.
    assert Vehicles.list() == [], "seed #{seed}: vehicles known before it started: #{inspect(Vehicles.list())}"
    proxy = start_supervised!({UDPProxy, gcs: gcs_port, seed: seed}, id: {:proxy, seed})
    {:ok, [1]} = Sim.start(count: 1, gcs: UDPProxy.port(proxy), speedup: @speedup)
    # Discovered on a clean link, then impaired.
    Wait.until(fn -> Vehicles.whereis(1) end, 250, fn -> "(vehicle 1 behind the proxy, seed #{seed})" end)
    :ok = UDPProxy.set(proxy, both: Enum.map(faults, fn {k, pct} -> {k, pct / 100} end))

    upload = Vehicles.upload_mission(1, uploaded)
    {:ok, info} = Sim.info(1)
    held = Enum.map(info.mission, &meaning/1) == Enum.map(tl(uploaded), &meaning/1)
    download = Vehicles.download_mission(1)
    stats = UDPProxy.stats(proxy)
    known = Vehicles.list()

    # The vehicle first: it would go on sending to the proxy's port, which
    # another test may have by then. Then the proxy, then what the ground
    # station heard through it (read to its end: GroundStation).
    :ok = Sim.stop()
    :ok = stop_supervised({:proxy, seed})
    Dolphin.Test.GroundStation.forget_vehicles()

    exact_download? =
      match?({:ok, back} when length(back) == length(uploaded), download) and
        Enum.map(tl(elem(download, 1)), &meaning/1) == Enum.map(tl(uploaded), &meaning/1) and
        Enum.all?(tl(elem(download, 1)), &(&1.frame == 3))

    # A lost final ACCEPTED leaves the upload unconfirmed: the download says.
    uploaded? = upload == :ok or match?({:error, %Dolphin.MissionError{result: :unconfirmed}}, upload)

    if uploaded? and held and exact_download? do
      nil
    else
      "seed #{seed} (#{inspect(faults)} %): upload #{outcome(upload)}, the vehicle holds the mission: #{held}, " <>
        "download #{if exact_download?, do: "exact", else: outcome(download)}, " <>
        "datagrams to the ground station #{stats.to_gcs.received} (#{stats.to_gcs.dropped} dropped), " <>
        "to the vehicle #{stats.to_vehicle.received} (#{stats.to_vehicle.dropped} dropped), vehicles known: #{inspect(known)}"
    end
  end

  defp outcome({:error, error}) when is_exception(error), do: "failed: " <> Exception.message(error)
  defp outcome({:ok, items}) when is_list(items), do: "#{length(items)} items, not as uploaded: #{inspect(Enum.map(items, &meaning/1), limit: 8)}"
  defp outcome(other), do: inspect(other)

  test "missions go up and come back exactly over up to 30 % loss each way, 10 % duplicates and 10 % reordering", %{gcs_port: gcs_port} do
    uploaded = items(30)
    failures = for seed <- @seeds, failure = transfer(gcs_port, seed, uploaded), do: failure
    assert failures == [], "#{length(failures)} of #{Enum.count(@seeds)} transfers failed:\n" <> Enum.join(failures, "\n")
  end
end
