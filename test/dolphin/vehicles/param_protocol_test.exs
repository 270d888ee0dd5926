defmodule Dolphin.Vehicles.ParamProtocolTest do
  # The ground station's parameter protocol (one parameter read or set, the
  # whole list) against a scripted vehicle that keeps parameters as
  # ArduPilot does (test/support/scripted_vehicle.ex), over UDP on
  # 127.0.0.1, clean and lossy: the same promises as the mission protocol's.
  # Its own Dolphin.Instance: async.
  use ExUnit.Case, async: true

  import Dolphin.Property

  alias :proper_types, as: T
  alias Dolphin.{Link, ParamError, Vehicles}
  alias Dolphin.Link.Connection
  alias Dolphin.Test.{ScriptedVehicle, Wait}

  doctest Dolphin.Vehicles.ParamProtocol
  doctest Dolphin.ParamError

  setup do
    Dolphin.Test.Instance.start!()
    name = "params-#{System.unique_integer([:positive])}"
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: name)
    Dolphin.Test.Instance.on_exit(fn -> DynamicSupervisor.terminate_child(Dolphin.Instance.names().links, link) end)
    %{port: Connection.port(name)}
  end

  defp vehicle(port, opts \\ []) do
    sysid = 30 + rem(System.unique_integer([:positive]), 200)
    {:ok, pid} = ScriptedVehicle.start_link([port: port, sysid: sysid] ++ opts)
    Wait.until(fn -> Vehicles.whereis(sysid) end)
    {sysid, pid}
  end

  # What the vehicle keeps, as the list should say it: typed, in name order.
  defp expected(vehicle) do
    kept = ScriptedVehicle.params(vehicle)
    kept |> Enum.sort() |> Enum.map(fn {name, value} -> {name, value} end)
  end

  defp listed(list), do: Enum.map(list, &{&1.name, &1.value})

  test "the whole list, typed; one read, one set read back; a refused value and an unknown name say so", %{port: port} do
    {sysid, vehicle} = vehicle(port)
    assert {:ok, list} = Vehicles.param_list(sysid)
    assert length(list) == 300
    assert listed(list) == expected(vehicle)
    assert Enum.map(list, & &1.index) == Enum.to_list(0..299)
    # Integer types read as integers, REAL32 as floats.
    assert %{type: 2, value: p0} = Enum.find(list, &(&1.name == "P0_GAIN"))
    assert is_integer(p0)
    assert %{type: 9, value: 0.375} = Enum.find(list, &(&1.name == "P3_TRIM"))

    assert {:ok, -6} = Vehicles.param(sysid, "P2_MAX", nil, [])
    assert {:ok, 42} = Vehicles.param(sysid, "P2_MAX", 42, [])
    assert ScriptedVehicle.params(vehicle)["P2_MAX"] == 42

    # P3_TRIM keeps within -10..10.
    assert {:error, %ParamError{result: :refused, kept: 10.0} = e} = Vehicles.param(sysid, "P3_TRIM", 25, [])
    assert Exception.message(e) == "vehicle #{sysid} kept P3_TRIM at 10 when asked for 25"

    assert {:error, %ParamError{result: :unknown} = e} = Vehicles.param(sysid, "P2_MAXX", nil, attempts: 2)
    assert Exception.message(e) =~ "vehicle #{sysid} has no parameter P2_MAXX (did you mean P2_MAX"
  end

  test "an unknown name is told by the whole list the vehicle gave last, with the link lost; not once its list has changed", %{port: port} do
    {sysid, vehicle} = vehicle(port)
    assert {:ok, _list} = Vehicles.param_list(sysid)

    # Nothing goes through: a name its list lacks is unknown all the same; one it has, not answered, is a timeout.
    ScriptedVehicle.set_faults(vehicle, loss: 1.0)
    assert {:error, %ParamError{result: :unknown} = e} = Vehicles.param(sysid, "P2_MAXX", nil, attempts: 1)
    assert Exception.message(e) =~ "did you mean P2_MAX"
    assert {:error, %ParamError{result: :timeout}} = Vehicles.param(sysid, "P2_MAX", nil, attempts: 1)

    # A parameter appears: a value with the new count says the list it gave is no longer its own, and a
    # name is judged by the list as it is now.
    ScriptedVehicle.set_faults(vehicle, loss: 0.0)
    :ok = ScriptedVehicle.add_param(vehicle, "P9_FRESH", 1.5)
    assert {:ok, 1.5} = Vehicles.param(sysid, "P9_FRESH", nil, [])
    assert {:error, %ParamError{result: :unknown} = e} = Vehicles.param(sysid, "P9_FRESHH", nil, attempts: 1)
    assert Exception.message(e) =~ "did you mean P9_FRESH"
  end

  # A link is measured over its latest twenty seconds or so: one that has
  # just got worse asks for fewer tries than it needs. However few, a read
  # goes on for the least patience (5 s of real time), as a command does;
  # at 20x a try on a measured link waits a few tens of milliseconds.
  test "a link that has just got worse: a read goes on for the least patience, past the tries its measured loss asks for", %{port: port} do
    Dolphin.Clock.set_speedup(20)
    {sysid, vehicle} = vehicle(port, timesync: true)
    # Measured clean: five tries (a few more once the silence below begins to count).
    Wait.until(fn -> match?({:ok, %{link: %{loss_out: loss}}} when loss != nil, Dolphin.Vehicles.Views.get(sysid)) end)
    tries = Dolphin.Vehicles.Retry.attempts(0.15)

    heard = fn kind ->
      n = Process.get(kind, 0) + Enum.count(ScriptedVehicle.take_param_requests(vehicle), &match?({^kind, _}, &1))
      Process.put(kind, n)
      n
    end

    ScriptedVehicle.set_faults(vehicle, silent: true)
    read = Task.async(fn -> Vehicles.param(sysid, "P2_MAX", nil, []) end)
    Wait.until(fn -> heard.(:name) > tries + 2 end)
    ScriptedVehicle.set_faults(vehicle, [])
    assert {:ok, -6} = Task.await(read)
  end

  # The mission protocol's promise, for parameters: up to 30 % loss each way,
  # 10 % duplicates and 10 % reordering, the list comes whole and exact, and
  # every value set is the one read back, every time.
  @tag timeout: 600_000
  test "up to 30 % loss, 10 % duplicates, 10 % reordering: every list exact, every set read back exact", %{port: port} do
    # The waits for answers are clock time: at 5x a fifth of their 1.5 s,
    # far more than a round trip on 127.0.0.1 takes; a round that brings
    # nothing is given up after twelve in a row (3.6 s: longer than a
    # loaded machine's pauses).
    Dolphin.Clock.set_speedup(5)
    {sysid, vehicle} = vehicle(port)

    check(
      forall({T.integer(0, 30), T.integer(0, 10), T.integer(0, 10), T.integer(0, 299), T.integer(-20, 100)}, fn {loss, dup, reorder, i, value} ->
        ScriptedVehicle.set_faults(vehicle, loss: loss / 100, duplicate: dup / 100, reorder: reorder / 100)
        faults = "#{loss} % loss, #{dup} % duplicates, #{reorder} % reordering"
        ScriptedVehicle.take_param_requests(vehicle)
        assert {:ok, list} = Vehicles.param_list(sysid), faults
        assert listed(list) == expected(vehicle), "#{faults}: the list read differs from the vehicle's"
        # Gaps are asked for by index; once they are, the whole list is not asked for again.
        requests = ScriptedVehicle.take_param_requests(vehicle)
        refute :list in Enum.drop_while(requests, &(&1 == :list)), "#{faults}: the list was asked for again after its gaps: #{inspect(requests)}"

        %{name: name, type: type} = Enum.at(list, i)
        set = if type == 9, do: value / 4, else: value

        case Vehicles.param(sysid, name, set, []) do
          {:ok, kept} -> assert kept == set and ScriptedVehicle.params(vehicle)[name] == set, "#{faults}: #{name} set to #{set}, kept #{kept}"
          {:error, %ParamError{result: :refused, kept: kept}} -> assert String.ends_with?(name, "_TRIM") and abs(kept) == 10.0, "#{faults}: #{name} refused #{set}"
        end

        ScriptedVehicle.set_faults(vehicle, [])
        true
      end),
      numtests: 15
    )
  end

  # Beyond the promise (60 % loss): a list is exact or a clear error, never a wrong value.
  @tag timeout: 300_000
  test "worse links: a list is exact or a clear error", %{port: port} do
    Dolphin.Clock.set_speedup(5)
    {sysid, vehicle} = vehicle(port, params: ScriptedVehicle.params(80))

    for loss <- [40, 60] do
      ScriptedVehicle.set_faults(vehicle, loss: loss / 100, duplicate: 0.2, reorder: 0.2)

      case Vehicles.param_list(sysid, attempts: 3) do
        {:ok, list} -> assert listed(list) == expected(vehicle)
        {:error, %ParamError{result: :timeout} = e} -> assert Exception.message(e) =~ ~r/parameters not received|no parameter received/
      end
    end
  end
end
