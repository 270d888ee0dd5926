defmodule Dolphin.Check.LiveFleet do
  @moduledoc """
  The fleet of `mix dolphin.check --connect ENDPOINT`: the vehicles that
  answer on the links within a wait, as the pre-flight check's dry run takes
  them (`Dolphin.Check.FleetFile`'s shape): their id, type, payloads,
  battery, position (as their home) and whether they fly. Nothing is sent to
  them; the links are closed and the vehicles forgotten again before the
  dry run, whose stand-ins take their ids.

      {:ok, fleet, skipped} = Dolphin.Check.LiveFleet.gather(["udpin:0.0.0.0:14550"], 5_000)
  """

    alias Dolphin.Vehicles

  @doc """
  Connects to `endpoints`, waits `wait_ms` (real time) for vehicles, and
  returns them, with the ids of those that did not report a position in
  time (left out). `{:error, %Dolphin.CommandLineError{reason: :failed}}` when a link cannot
  be opened or no vehicle answered.
  """
  @spec gather([String.t()], non_neg_integer()) :: {:ok, [Dolphin.Check.FleetFile.vehicle()], [non_neg_integer()]} | {:error, Dolphin.CommandLineError.t()}
  def gather(endpoints, wait_ms) do
    before = MapSet.new(Vehicles.list())

    with {:ok, links} <- connect(endpoints, []) do
      try do
        Process.sleep(wait_ms)
        ids = Enum.reject(Vehicles.list(), &MapSet.member?(before, &1))
        views = for id <- ids, {:ok, v} <- [Vehicles.view(id)], do: v
        {known, unknown} = Enum.split_with(views, &(&1.position != nil))

        case known do
          [] -> {:error, Dolphin.CommandLineError.failed("--connect #{Enum.join(endpoints, " ")}", "no vehicle reported its position within #{div(wait_ms, 1000)} s")}
          _ -> {:ok, Enum.map(known, &vehicle/1), Enum.map(unknown, & &1.id)}
        end
      after
        Enum.each(links, &Dolphin.Link.disconnect/1)
        for id <- Vehicles.list(), not MapSet.member?(before, id), do: Vehicles.forget(id)
      end
    end
  end

  defp connect([], links), do: {:ok, links}

  defp connect([ep | rest], links) do
    case Dolphin.Link.connect(ep) do
      {:ok, pid} ->
        connect(rest, [pid | links])

      {:error, why} ->
        Enum.each(links, &Dolphin.Link.disconnect/1)
        {:error, Dolphin.CommandLineError.failed("--connect #{ep}", why)}
    end
  end

  defp vehicle(v) do
    %{
      id: v.id,
      type: v.type || :uav,
      # As heard: a vehicle of unknown airframe stands in as one (raw missions only).
      airframe: v.airframe,
      payloads: v.payloads,
      battery: v.battery || 1.0,
      position: v.position,
      airborne?: v.landed in [:in_air, :takeoff, :landing] or (v.relative_altitude || 0.0) > 1.0
    }
  end
end
