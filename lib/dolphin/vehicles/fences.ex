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
