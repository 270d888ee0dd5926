defmodule Dolphin.Console.Arguments do
  @moduledoc false
  # Pure argument checks of the console's helpers: each returns {:ok, value}
  # or {:error, %UsageError{}} whose message an operator can act on. The
  # vehicle check works on a snapshot of what the ground station knows
  # (Dolphin.Console.Overview).

  alias Dolphin.Console.UsageError

  @typedoc """
  What the console knows of a vehicle: `mavlink?` (it has a MAVLink state;
  false for fake vehicles of the fake platform), `lost?`, `silent_ms` (clock
  time since the last frame), `task` (the platform task flying it:
  %{task_id, kind, name, run} or nil).
  """
  @type info :: %{mavlink?: boolean(), lost?: boolean(), silent_ms: integer() | nil, task: map() | nil}

  @doc false
  # Whether a helper may act on vehicle `id`. `needs`: :control (a command
  # that changes what the vehicle does), :link (it talks to the vehicle but
  # changes nothing), :any (reads what the ground station already has).
  # {:ok, :free}, {:ok, {:stop_first, task}} (force: true and a task flies
  # it), or {:error, %UsageError{}}.
  @spec vehicle(term(), %{Dolphin.Vehicles.Id.t() => info()}, :control | :link | :any, boolean()) ::
          {:ok, :free | {:stop_first, map()}} | {:error, UsageError.t()}
  def vehicle(id, known, needs, force \\ false)

  def vehicle(id, known, needs, force) do
    if Dolphin.Vehicles.Id.valid?(id), do: known_vehicle(id, known, needs, force), else: {:error, %UsageError{reason: :not_a_vehicle_id, value: id}}
  end

  defp known_vehicle(id, known, needs, force) do
    case Map.fetch(known, id) do
      :error ->
        {:error, %UsageError{reason: :unknown_vehicle, value: id, detail: known |> Map.keys() |> Enum.sort()}}

      {:ok, info} ->
        cond do
          needs != :any and not info.mavlink? ->
            {:error, %UsageError{reason: :fake_vehicle, value: id}}

          needs != :any and info.lost? ->
            {:error, %UsageError{reason: :lost, value: id, detail: info.silent_ms}}

          needs == :control and info.task != nil and not force ->
            {:error, %UsageError{reason: :busy, value: id, detail: info.task}}

          needs == :control and info.task != nil ->
            {:ok, {:stop_first, info.task}}

          true ->
            {:ok, :free}
        end
    end
  end

  @doc false
  # A mode name: :guided, "GUIDED", "guided", :GUIDED -> :guided.
  @spec mode(term()) :: {:ok, atom()} | {:error, UsageError.t()}
  def mode(mode) when is_atom(mode) and mode not in [nil, true, false], do: mode(Atom.to_string(mode))

  def mode(mode) when is_binary(mode) do
    name = mode |> String.trim() |> String.downcase()

    # Every mode's atom exists once the mode tables (Dolphin.Vehicles.Modes) are loaded.
    Code.ensure_loaded(Dolphin.Vehicles.Modes)

    if name =~ ~r/^[a-z][a-z0-9_]*$/ do
      {:ok, String.to_existing_atom(name)}
    else
      {:error, %UsageError{reason: :not_a_mode, value: mode}}
    end
  rescue
    ArgumentError -> {:error, %UsageError{reason: :no_such_mode, value: mode}}
  end

  def mode(other), do: {:error, %UsageError{reason: :not_a_mode, value: other}}

  # ArduCopter modes flown by a pilot's sticks: without RC throttle the copter sinks.
  @pilot_modes [:stabilize, :acro, :alt_hold, :loiter, :poshold, :sport, :drift, :flowhold]

  @doc false
  # Refuses a pilot-controlled mode for a copter in the air (ARDUPILOT.md:
  # with no RC throttle it descends, lands and disarms) unless forced.
  @spec pilot_mode(atom(), boolean(), boolean()) :: :ok | {:error, UsageError.t()}
  def pilot_mode(mode, in_air?, force) do
    if mode in @pilot_modes and in_air? and not force,
      do: {:error, %UsageError{reason: :pilot_mode, value: mode}},
      else: :ok
  end

  @doc false
  @spec altitude(term()) :: {:ok, number()} | {:error, UsageError.t()}
  def altitude(alt) when is_number(alt) and alt > 0 and alt <= 10_000, do: {:ok, alt}
  def altitude(alt), do: {:error, %UsageError{reason: :bad_altitude, value: alt}}

  @doc false
  @spec position(term(), term(), term()) :: {:ok, {number(), number(), number()}} | {:error, UsageError.t()}
  def position(lat, lon, alt) do
    cond do
      not (is_number(lat) and lat >= -90 and lat <= 90) -> {:error, %UsageError{reason: :bad_latitude, value: lat}}
      not (is_number(lon) and lon >= -180 and lon <= 180) -> {:error, %UsageError{reason: :bad_longitude, value: lon}}
      not is_number(alt) -> {:error, %UsageError{reason: :bad_position_altitude, value: alt}}
      true -> {:ok, {lat, lon, alt}}
    end
  end

  @doc false
  # A wait or a period in milliseconds.
  @spec ms(term(), atom()) :: {:ok, non_neg_integer()} | {:error, UsageError.t()}
  def ms(n, _what) when is_integer(n) and n >= 0, do: {:ok, n}
  def ms(n, what), do: {:error, %UsageError{reason: :bad_ms, value: n, detail: what}}

  @doc false
  @spec count(term()) :: {:ok, pos_integer()} | {:error, UsageError.t()}
  def count(n) when is_integer(n) and n > 0, do: {:ok, n}
  def count(n), do: {:error, %UsageError{reason: :bad_count, value: n}}

  @doc false
  # Keyword options of a helper: unknown keys are a mistake worth saying.
  @spec options(term(), [atom()]) :: {:ok, keyword()} | {:error, UsageError.t()}
  def options(opts, allowed) do
    cond do
      not Keyword.keyword?(opts) ->
        {:error, %UsageError{reason: :not_options, value: opts, detail: allowed}}

      (unknown = Keyword.keys(opts) -- allowed) != [] ->
        {:error, %UsageError{reason: :unknown_options, value: unknown, detail: allowed}}

      true ->
        {:ok, opts}
    end
  end
end
