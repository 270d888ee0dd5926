defmodule Dolphin.Vehicles.Fences do
  @moduledoc """
  A `Dolphin.Fence` put on a vehicle, as its autopilot keeps one: the
  fence's zones uploaded as the fence list of the mission protocol, its
  rally points as the rally list (each cleared first, uploaded, read back
  and compared), its breach action, ceiling and floor as FENCE_ACTION,
  FENCE_ALT_MAX and FENCE_ALT_MIN, what it has as FENCE_TYPE, and the fence
  enabled (FENCE_ENABLE 1: turned off first, since ArduPilot takes a new
  FENCE_TYPE only when the fence is enabled again).

  Nothing is half done without being said: each step's refusal ends it with
  `{:error, exception}` — the transfer's (`Dolphin.MissionError`), a
  parameter's (`Dolphin.ParamError`), or `Dolphin.Mission.MismatchError`
  for a list read back otherwise than it was sent — and the fence is left
  disabled.

  A vehicle is given back as it was found: before its fence is first
  changed, its fence and rally lists and FENCE_* parameters are read and
  kept (`Dolphin.Vehicles.Settings`), and `give_back/2` (which the fleet
  calls when the vehicle is released, `Dolphin.Fleet.MAVLinkSource`) puts
  them back.
  """

  alias Dolphin.{Airframe, Fence, Vehicles}
  alias Dolphin.Mission.MismatchError

  @doc """
  Puts `fence` on vehicle `id` (of `airframe`, whose firmware's breach
  action it is given), with rally heights above `home`.
  """
  @spec apply(Vehicles.Id.t(), Fence.t(), Dolphin.Geo.Location.t(), atom() | nil, keyword()) :: :ok | {:error, Exception.t()}
  def apply(id, %Fence{} = fence, home, airframe, opts \\ []) do
    items = Fence.to_items(fence, home)

    with {:ok, action} <- action(id, fence, airframe),
         :ok <- keep_found(id, opts),
         {:ok, _} <- Vehicles.set_param(id, "FENCE_ENABLE", 0, opts),
         :ok <- put_list(id, :fence, items.fence, opts),
         :ok <- put_list(id, :rally, items.rally, opts),
         {:ok, _} <- Vehicles.set_param(id, "FENCE_ACTION", action, opts),
         :ok <- altitude(id, "FENCE_ALT_MAX", fence.max_altitude, opts),
         :ok <- altitude(id, "FENCE_ALT_MIN", fence.min_altitude, opts),
         {:ok, _} <- Vehicles.set_param(id, "FENCE_TYPE", Fence.type_bits(fence), opts),
         {:ok, _} <- enable(id, fence, opts) do
      :ok
    end
  end

  @params ["FENCE_ENABLE", "FENCE_TYPE", "FENCE_ACTION", "FENCE_ALT_MAX", "FENCE_ALT_MIN"]

  @doc """
  Gives vehicle `id` its fence back as it was before this ground station
  first changed it: `:ok` (also when nothing was changed), or the
  refusal that stopped it.
  """
  @spec give_back(Vehicles.Id.t(), keyword()) :: :ok | {:error, Exception.t()}
  def give_back(id, opts \\ []) do
    case Vehicles.Settings.take_found_fence(id) do
      :none ->
        :ok

      {:ok, found} ->
        with {:ok, _} <- Vehicles.set_param(id, "FENCE_ENABLE", 0, opts),
             :ok <- put_list(id, :fence, found.fence, opts),
             :ok <- put_list(id, :rally, found.rally, opts),
             :ok <- Enum.reduce_while(@params -- ["FENCE_ENABLE"], :ok, fn name, :ok -> param_back(id, name, found.params, opts) end),
             {:ok, _} <- Vehicles.set_param(id, "FENCE_ENABLE", Map.fetch!(found.params, "FENCE_ENABLE"), opts) do
          :ok
        end
    end
  end

  @doc """
  Waits (at most `real_ms` of real time) until every released vehicle has
  been given its fence back: what a run does before it closes its links.
  `:ok`, or `:timeout` with some still under way.
  """
  @spec await_returns(non_neg_integer()) :: :ok | :timeout
  def await_returns(real_ms) do
    deadline = System.monotonic_time(:millisecond) + real_ms

    Stream.repeatedly(fn -> Task.Supervisor.children(Dolphin.Vehicles.FenceReturns) end)
    |> Enum.find_value(fn
      [] -> :ok
      _ -> if System.monotonic_time(:millisecond) > deadline, do: :timeout, else: Process.sleep(20) && nil
    end)
  end

  defp param_back(id, name, params, opts) do
    case Vehicles.set_param(id, name, Map.fetch!(params, name), opts) do
      {:ok, _} -> {:cont, :ok}
      error -> {:halt, error}
    end
  end

  # What the vehicle had before its first fence from here.
  defp keep_found(id, opts) do
    if Vehicles.Settings.found_fence?(id) do
      :ok
    else
      with {:ok, fence} <- Vehicles.download_mission(id, Keyword.put(opts, :mission_type, :fence)),
           {:ok, rally} <- Vehicles.download_mission(id, Keyword.put(opts, :mission_type, :rally)),
           {:ok, params} <- read_params(id, opts) do
        Vehicles.Settings.put_found_fence(id, %{fence: renumbered(fence), rally: renumbered(rally), params: params})
        :ok
      end
    end
  end

  defp read_params(id, opts) do
    Enum.reduce_while(@params, {:ok, %{}}, fn name, {:ok, acc} ->
      case Vehicles.read_param(id, name, opts) do
        {:ok, value} -> {:cont, {:ok, Map.put(acc, name, value)}}
        error -> {:halt, error}
      end
    end)
  end

  # Read back in the frames ArduPilot keeps (0, 3): sent again as they came.
  defp renumbered(items), do: items |> Enum.with_index() |> Enum.map(fn {item, seq} -> %{item | seq: seq} end)

  defp action(id, fence, airframe) do
    module = Airframe.of(airframe)

    case module.fence_action(fence.on_breach) do
      nil ->
        {:error,
         %ArgumentError{
           message:
             "vehicle #{id}: #{module.firmware()}'s fence has no action for on_breach #{inspect(fence.on_breach)} (#{Enum.join(for(a <- Fence.actions(), module.fence_action(a), do: inspect(a)), ", ")})"
         }}

      action ->
        {:ok, action}
    end
  end

  # A fence of nothing (only rally points) is left disabled.
  defp enable(id, fence, opts), do: if(Fence.type_bits(fence) == 0, do: {:ok, 0.0}, else: Vehicles.set_param(id, "FENCE_ENABLE", 1, opts))

  defp altitude(_id, _name, nil, _opts), do: :ok

  defp altitude(id, name, metres, opts) do
    with {:ok, _} <- Vehicles.set_param(id, name, metres, opts), do: :ok
  end

  # Cleared first: ArduPilot erases a small fence uploaded over a larger one.
  defp put_list(id, type, items, opts) do
    with :ok <- Vehicles.clear_mission(id, Keyword.put(opts, :mission_type, type)),
         :ok <- upload(id, type, items, opts),
         {:ok, back} <- Vehicles.download_mission(id, Keyword.put(opts, :mission_type, type)) do
      compare(type, items, back)
    end
  end

  defp upload(_id, _type, [], _opts), do: :ok
  defp upload(id, type, items, opts), do: Vehicles.upload_mission(id, items, Keyword.put(opts, :mission_type, type))

  @doc """
  Whether a fence or rally list read back is the one sent: the same
  commands at the same places (degE7), a polygon's corner count and a
  circle's radius (to the centimetre), a rally point's height; frames and
  the params ArduPilot does not keep are not compared.
  """
  @spec compare(:fence | :rally, [struct()], [struct()]) :: :ok | {:error, MismatchError.t()}
  def compare(_type, sent, back) when length(sent) != length(back),
    do: {:error, %MismatchError{what: :count, on_vehicle: length(back), uploaded: length(sent)}}

  def compare(type, sent, back) do
    sent
    |> Enum.zip(back)
    |> Enum.find_value(:ok, fn {up, down} ->
      differs = fn what, on_vehicle, uploaded -> {:error, %MismatchError{what: what, item: up.seq, on_vehicle: on_vehicle, uploaded: uploaded}} end

      cond do
        up.command != down.command -> differs.(:command, down.command, up.command)
        {up.x, up.y} != {down.x, down.y} -> differs.(:position, {down.x, down.y}, {up.x, up.y})
        type == :fence and abs(down.param1 - up.param1) > 0.01 -> differs.(:param1, down.param1, up.param1)
        type == :rally and abs(down.z - up.z) > 0.01 -> differs.(:height, down.z, up.z)
        true -> nil
      end
    end)
  end
end
