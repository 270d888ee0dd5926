defmodule Dolphin.Console.ArgumentsTest do
  use ExUnit.Case, async: true

  alias Dolphin.Console.{Arguments, UsageError}

  doctest UsageError
  doctest Dolphin.Console.RunError

  @task %{task_id: 17, kind: :mission, name: "Survey Area", run: 14, vehicle: 1, parent_id: 15}

  @known %{
    1 => %{mavlink?: true, lost?: false, silent_ms: 100, task: @task},
    2 => %{mavlink?: true, lost?: false, silent_ms: 100, task: nil},
    3 => %{mavlink?: true, lost?: true, silent_ms: 23_400, task: nil},
    7 => %{mavlink?: false, lost?: false, silent_ms: nil, task: nil}
  }

  describe "vehicle ids" do
    test "a free vehicle may be told anything" do
      for needs <- [:control, :link, :any], do: assert(Arguments.vehicle(2, @known, needs) == {:ok, :free})
    end

    test "not an id, an unknown id, no vehicles at all" do
      assert "a vehicle is given by its id as vehicles() lists it" <> _ = why = message(Arguments.vehicle("1", @known, :control))
      assert why =~ ~s(got: "1")
      assert Arguments.vehicle(-1, @known, :any) |> elem(0) == :error
      assert "no vehicle 9: the known vehicles are 1, 2, 3, 7 (see vehicles())" = message(Arguments.vehicle(9, @known, :any))
      assert "no vehicle 9: no vehicle is known yet" <> _ = message(Arguments.vehicle(9, %{}, :control))
    end

    test "a lost vehicle is sent nothing, but what the ground station has of it can be read" do
      why = message(Arguments.vehicle(3, @known, :control))
      assert why =~ "vehicle 3 is lost (nothing heard for 23.4 s): nothing sent"
      assert {:error, %UsageError{}} = Arguments.vehicle(3, @known, :link)
      assert {:ok, :free} = Arguments.vehicle(3, @known, :any)
    end

    test "a fake vehicle takes no MAVLink" do
      assert "vehicle 7 is a fake vehicle of the fake platform" <> _ = message(Arguments.vehicle(7, @known, :control))
      assert {:ok, :free} = Arguments.vehicle(7, @known, :any)
    end

    test "a vehicle flying a task: commands say they would stop it, and with force they do" do
      why = message(Arguments.vehicle(1, @known, :control))
      assert why =~ ~s[vehicle 1 is flying task 17 mission "Survey Area" (run 14): nothing sent]
      assert why =~ "force: true to stop that task first"
      assert Arguments.vehicle(1, @known, :control, true) == {:ok, {:stop_first, @task}}
      # Reading from it disturbs nothing.
      assert Arguments.vehicle(1, @known, :link) == {:ok, :free}
      # A lost vehicle is refused even with force.
      assert {:error, %UsageError{}} = Arguments.vehicle(3, @known, :control, true)
    end
  end

  test "modes by any spelling" do
    assert Arguments.mode(:guided) == {:ok, :guided}
    assert Arguments.mode("BRAKE") == {:ok, :brake}
    assert Arguments.mode(:ALT_HOLD) == {:ok, :alt_hold}
    assert "a mode is a name" <> _ = message(Arguments.mode(4))
    assert {:error, %UsageError{}} = Arguments.mode("not a mode!")
    assert "no flight mode is called \"warp_drive_xyz\"" = message(Arguments.mode("warp_drive_xyz"))
    assert {:error, %UsageError{}} = Arguments.mode(nil)
  end

  test "pilot modes are refused in the air unless forced" do
    why = message(Arguments.pilot_mode(:loiter, true, false))
    assert why =~ "LOITER is flown by a pilot's sticks"
    assert why =~ "hold/1"
    assert Arguments.pilot_mode(:loiter, true, true) == :ok
    assert Arguments.pilot_mode(:loiter, false, false) == :ok
    assert Arguments.pilot_mode(:brake, true, false) == :ok
  end

  test "numbers" do
    assert Arguments.altitude(20) == {:ok, 20}
    assert "an altitude is a number of metres above home" <> _ = message(Arguments.altitude(0))
    assert {:error, %UsageError{}} = Arguments.altitude("20")
    assert Arguments.position(40.1, -7.2, 30) == {:ok, {40.1, -7.2, 30}}
    assert "latitude must be degrees in -90..90, got: 91" = message(Arguments.position(91, 0, 0))
    assert "longitude" <> _ = message(Arguments.position(0, -181, 0))
    assert "altitude" <> _ = message(Arguments.position(0, 0, :high))
    assert Arguments.ms(0, :wait) == {:ok, 0}
    assert "wait: takes milliseconds" <> _ = message(Arguments.ms(-1, :wait))
    assert Arguments.count(5) == {:ok, 5}
    assert {:error, %UsageError{}} = Arguments.count(0)
  end

  test "options" do
    assert Arguments.options([force: true], [:force]) == {:ok, [force: true]}
    assert "unknown option :forse; options are :force" = message(Arguments.options([forse: true], [:force]))
    assert "options are a keyword list" <> _ = message(Arguments.options(:force, [:force]))
  end

  test "errors name the check that failed" do
    assert {:error, %UsageError{reason: :unknown_vehicle, value: 9, detail: [1, 2, 3, 7]}} = Arguments.vehicle(9, @known, :any)
    assert {:error, %UsageError{reason: :busy, value: 1, detail: @task}} = Arguments.vehicle(1, @known, :control)
    assert {:error, %UsageError{reason: :no_such_mode}} = Arguments.mode("warp_drive_xyz")
    assert {:error, %UsageError{reason: :unknown_options, value: [:forse], detail: [:force]}} = Arguments.options([forse: true], [:force])
  end

  defp message(result) do
    assert {:error, %UsageError{} = e} = result
    Exception.message(e)
  end
end
