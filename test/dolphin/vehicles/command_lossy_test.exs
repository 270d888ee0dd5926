defmodule Dolphin.Vehicles.CommandLossyTest do
  # Commands to a scripted vehicle (test/support/scripted_vehicle.ex) over a link that
  # drops, duplicates and reorders frames both ways. Its own Dolphin.Instance (its
  # vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  import Dolphin.Property

  alias :proper_types, as: T
  alias Dolphin.{Clock, CommandError, Link, Vehicles}
  alias Dolphin.Link.Connection
  alias Dolphin.Test.ScriptedVehicle

  @speedup 50
  # The scripted vehicle answers any COMMAND_LONG: each command of this test
  # gets an id of its own, counting up from here (see below).
  @first_id 20_000

  setup do
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", name: "cmd-lossy")
    Clock.set_speedup(@speedup)
    sysid = 230
    {:ok, vehicle} = ScriptedVehicle.start_link(port: Connection.port("cmd-lossy"), sysid: sysid, speedup: @speedup, seed: 7)

    Dolphin.Test.Instance.on_exit(fn ->
      Clock.set_speedup(1)
      DynamicSupervisor.terminate_child(Dolphin.Instance.names().links, link)
      Vehicles.forget(sysid)
    end)

    Dolphin.Test.Wait.until(fn -> Vehicles.whereis(sysid) end)
    %{vehicle: vehicle, sysid: sysid}
  end

  # Either the vehicle accepted the command and the caller hears :ok, or it
  # refused it and the caller hears so, or the caller hears that nothing came
  # back; never :ok for a refused or unseen command.
  #
  # COMMAND_ACK carries no sequence number: a late duplicate of the ack of an
  # earlier command with the same id cannot be told from the answer to a new
  # one (a limit of the protocol, for every ground station), and a busy machine
  # can delay a duplicate past any pause. So no two commands here share an id.
  @tag timeout: 120_000
  test "a lossy link never turns a refused or lost command into success", %{vehicle: vehicle, sysid: sysid} do
    check(
      forall({T.integer(0, 40), T.integer(0, 20), T.integer(0, 20), T.non_empty(T.list(T.integer(0, 9)))}, fn {loss, dup, reorder, params} ->
        ScriptedVehicle.set_faults(vehicle, loss: loss / 100, duplicate: dup / 100, reorder: reorder / 100)

        for p1 <- params do
          command = Process.get(:next_id, @first_id)
          Process.put(:next_id, command + 1)
          assert command <= 65_535

          before = length(ScriptedVehicle.commands(vehicle))

          # Without loss every command is answered, however late a busy machine
          # lets the answer through: a long ack timeout, so that a timeout here
          # can only mean an answer that never came.
          opts = if loss == 0, do: [attempts: 6, ack_timeout_ms: 3_600_000], else: [attempts: 6]

          case Vehicles.command(sysid, command, [p1], opts) do
            {:ok, :accepted} ->
              assert rem(p1, 2) == 0, "command #{command} with param1 #{p1} was refused, yet reported accepted"
              assert Enum.drop(ScriptedVehicle.commands(vehicle), before) |> Enum.any?(&(&1 == {command, p1 * 1.0}))

            {:error, %CommandError{result: :denied}} ->
              assert rem(p1, 2) == 1

            {:error, %CommandError{result: :timeout}} ->
              assert loss > 0
          end
        end

        ScriptedVehicle.set_faults(vehicle, [])
        # Let late duplicates of this run's acks drain before the next run.
        Process.sleep(30)
        true
      end),
      numtests: 40
    )
  end
end
