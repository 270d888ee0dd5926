defmodule Dolphin.Fleet.MAVLinkSource do
  @moduledoc """
  The vehicles of `Dolphin.Vehicles` (real MAVLink vehicles, or the simulator's)
  as a `Dolphin.Fleet.Source`; its `arg` is unused.

  Each vehicle's process publishes its `Dolphin.Vehicles.View` (see
  `Dolphin.Vehicles.View.of/3`): the heartbeat's MAV_TYPE as a class and an
  airframe, payloads from its components (a camera component gives
  `:camera`) plus those given to it (`Dolphin.Vehicles.put_payloads/2`, a
  fleet file's: `--fleet FILE`) and configured ones (`config :dolphin,
  vehicle_payloads: %{2 => [:sidescan]}`), battery,
  position, relative altitude, mode, armed, landed state, mission progress,
  link figures, read from `Dolphin.Vehicles.Views`, which already publishes
  and emits what a source must (including vehicles heard by other nodes
  and put there).
  """

  @behaviour Dolphin.Fleet.Source

  require Logger

  @impl true
  def list(_arg), do: Dolphin.Vehicles.list()

  @impl true
  def vehicle(_arg, id), do: Dolphin.Vehicles.view(id)

  @impl true
  def views(_arg), do: Dolphin.Vehicles.Views.all()

  @impl true
  # Each released vehicle whose fence was changed gets it back, in a task
  # of its own (a transfer takes seconds; the fleet does not wait).
  def released(_arg, ids) do
    instance = Dolphin.Instance.current()

    for id <- ids, Dolphin.Vehicles.Settings.found_fence?(id) do
      Task.Supervisor.start_child(Dolphin.Vehicles.FenceReturns, fn ->
        Dolphin.Instance.put(instance)

        case Dolphin.Vehicles.Fences.give_back(id) do
          :ok -> :ok
          {:error, e} -> Logger.warning("vehicle #{id}: its fence could not be given back as it was found: #{Exception.message(e)}")
        end
      end)
    end

    :ok
  end

  @impl true
  def set_timeout(_arg, id, ms), do: Dolphin.Vehicles.set_timeout(id, ms)

  @impl true
  def send_message(_arg, id, message), do: Dolphin.Vehicles.send_message(id, message)

  @impl true
  def param(_arg, id, name, value), do: Dolphin.Vehicles.param(id, name, value, [])
end
