defmodule Dolphin.Check.Source do
  @moduledoc false
  # The vehicles of a pre-flight check: stand-ins for the described fleet
  # (a `Dolphin.Fleet.FakeSource` holds their views, so picks, allocation and
  # conditions see them as they see real vehicles) that fly no mission.
  # The dry run's context has `Dolphin.Mission.Platform` hand each mission to
  # `fly/4` (its `platform_opts`, `missions: {Dolphin.Check.Source, arg}`):
  # the mission is checked and estimated (Dolphin.Check.Recorder) and a
  # `Dolphin.Check.Flight` passes its time.

  @behaviour Dolphin.Fleet.Source

  alias Dolphin.Fleet.FakeSource

  @type arg :: %{test: atom(), recorder: pid()}

  @impl true
  def list(%{test: t}), do: FakeSource.list(t)

  @impl true
  def vehicle(%{test: t}, id), do: FakeSource.vehicle(t, id)

  @impl true
  def views(%{test: t}), do: FakeSource.views(t)

  @impl true
  def set_timeout(%{test: t}, id, ms), do: FakeSource.set_timeout(t, id, ms)

  @impl true
  def send_message(%{test: t}, id, message), do: FakeSource.send_message(t, id, message)

  # A stand-in's parameters are unknown to the check: a read gives 0 (the
  # script goes on), a set is kept.
  @impl true
  def param(%{test: t}, id, name, value) do
    case FakeSource.param(t, id, name, value) do
      {:error, %Dolphin.ParamError{result: :unknown}} -> {:ok, 0}
      other -> other
    end
  end

  @doc false
  # Called by Dolphin.Mission.Platform.start/3 in the engine's leaf process,
  # whose context names the script's code process (the line it is at).
  @spec fly(arg(), Dolphin.Mission.t(), non_neg_integer(), keyword()) :: {:ok, pid()}
  def fly(%{test: t, recorder: recorder}, mission, vehicle, opts) do
    line = script_line(Dolphin.Engine.Context.current().owner)
    # Checked with the fence it would fly with: its own, else the script's.
    now_ms = (opts[:clock] || Dolphin.Check.Clock).now_ms()
    estimate = Dolphin.Check.Recorder.mission(recorder, %{mission | fence: mission.fence || opts[:fence]}, vehicle, line, now_ms, opts[:min_separation])
    Dolphin.Check.Flight.start_link(%{test: t, recorder: recorder, vehicle: vehicle, estimate: estimate, owner: opts[:owner], clock: opts[:clock]})
  end

  # The script line its code process is at (`execute` waits there), read
  # from its process dictionary (Dolphin.Script.Statements.__line__/1).
  defp script_line(pid) when is_pid(pid) do
    case Process.info(pid, :dictionary) do
      {:dictionary, dict} -> Keyword.get(dict, :"$dolphin_line")
      nil -> nil
    end
  end

  defp script_line(_), do: nil
end
