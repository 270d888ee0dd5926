defmodule Dolphin.Console.UsageError do
  @moduledoc """
  A console helper called with something it cannot act on, in words an
  operator can act on. `reason` names the check that failed, `value` is
  what was given, `detail` what the message needs besides:

    * vehicles: `:not_a_vehicle_id`, `:unknown_vehicle` (`detail`: the known
      ids), `:fake_vehicle`, `:lost` (`detail`: ms since last heard),
      `:busy` (`detail`: the task flying it);
    * modes: `:not_a_mode`, `:no_such_mode`, `:pilot_mode` (a mode flown by
      a pilot's sticks, refused in the air);
    * numbers: `:bad_altitude`, `:bad_latitude`, `:bad_longitude`,
      `:bad_position_altitude`, `:bad_ms` (`detail`: what waits), `:bad_count`;
    * options: `:not_options` (`detail`: the allowed keys),
      `:unknown_options` (`value`: the unknown keys, `detail`: the allowed).

      iex> Exception.message(%Dolphin.Console.UsageError{reason: :unknown_vehicle, value: 9, detail: [1, 2]})
      "no vehicle 9: the known vehicles are 1, 2 (see vehicles())"
  """

  alias Dolphin.Console.Format

  defexception [:reason, :value, :detail]

  @type reason ::
          :not_a_vehicle_id
          | :unknown_vehicle
          | :fake_vehicle
          | :lost
          | :busy
          | :not_a_mode
          | :no_such_mode
          | :pilot_mode
          | :bad_altitude
          | :bad_latitude
          | :bad_longitude
          | :bad_position_altitude
          | :bad_ms
          | :bad_count
          | :not_options
          | :unknown_options

  @type t :: %__MODULE__{reason: reason(), value: term(), detail: term()}

  @impl true
  def message(%__MODULE__{reason: reason, value: value, detail: detail}), do: text(reason, value, detail)

  defp text(:not_a_vehicle_id, other, _), do: "a vehicle is given by its id as vehicles() lists it (a system id, or a name \"SYSID@NETWORK\" for another vehicle with that system id), got: #{inspect(other)}"
  defp text(:unknown_vehicle, id, []), do: "no vehicle #{id}: no vehicle is known yet (is a link connected? see vehicles())"
  defp text(:unknown_vehicle, id, known), do: "no vehicle #{id}: the known vehicles are #{Enum.join(known, ", ")} (see vehicles())"
  defp text(:fake_vehicle, id, _), do: "vehicle #{id} is a fake vehicle of the fake platform: it takes no MAVLink commands"

  defp text(:lost, id, silent_ms),
    do: "vehicle #{id} is lost (nothing heard for #{Format.duration(silent_ms || 0)}): nothing sent; check its link (vehicles())"

  defp text(:busy, id, task) do
    "vehicle #{id} is flying task #{Format.task_label(task)} (run #{task.run}): nothing sent. " <>
      "Add force: true to stop that task first (the vehicle holds; the task's parent goes on as if it had completed)"
  end

  defp text(:not_a_mode, other, _), do: "a mode is a name such as :guided or \"BRAKE\", got: #{inspect(other)}"
  defp text(:no_such_mode, mode, _), do: "no flight mode is called #{inspect(mode)}"

  defp text(:pilot_mode, mode, _) do
    "#{Format.mode(mode)} is flown by a pilot's sticks: with no RC throttle the copter sinks, lands and disarms. " <>
      "hold/1 holds position (BRAKE, else GUIDED); add force: true to set #{Format.mode(mode)} anyway"
  end

  defp text(:bad_altitude, alt, _), do: "an altitude is a number of metres above home, more than 0, got: #{inspect(alt)}"
  defp text(:bad_latitude, lat, _), do: "latitude must be degrees in -90..90, got: #{inspect(lat)}"
  defp text(:bad_longitude, lon, _), do: "longitude must be degrees in -180..180, got: #{inspect(lon)}"
  defp text(:bad_position_altitude, alt, _), do: "altitude must be a number of metres, got: #{inspect(alt)}"
  defp text(:bad_ms, n, what), do: "#{what}: takes milliseconds (an integer, 0 or more), got: #{inspect(n)}"
  defp text(:bad_count, n, _), do: "a count is a positive integer, got: #{inspect(n)}"
  defp text(:not_options, opts, allowed), do: "options are a keyword list (#{Enum.map_join(allowed, ", ", &"#{&1}: ...")}), got: #{inspect(opts)}"

  defp text(:unknown_options, unknown, allowed),
    do: "unknown option#{if length(unknown) > 1, do: "s"} #{Enum.map_join(unknown, ", ", &inspect/1)}; options are #{Enum.map_join(allowed, ", ", &inspect/1)}"
end
