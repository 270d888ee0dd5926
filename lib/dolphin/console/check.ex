defmodule Dolphin.Console.Check do
  @moduledoc false
  # Pure argument checks of the console's helpers: each returns {:ok, value}
  # or {:error, text an operator can act on}. The vehicle check works on a
  # snapshot of what the ground station knows (Dolphin.Console.Snapshot).

  alias Dolphin.Console.Format

  @typedoc """
  What the console knows of a vehicle: `mavlink?` (it has a MAVLink state;
  false for fake vehicles of the test platform), `lost?`, `silent_ms` (clock
  time since the last frame), `task` (the platform task flying it:
  %{task_id, kind, name, run} or nil).
  """
  @type info :: %{mavlink?: boolean(), lost?: boolean(), silent_ms: integer() | nil, task: map() | nil}

  @doc false
  # Whether a helper may act on vehicle `id`. `needs`: :control (a command
  # that changes what the vehicle does), :link (it talks to the vehicle but
  # changes nothing), :any (reads what the ground station already has).
  # {:ok, :free}, {:ok, {:stop_first, task}} (force: true and a task flies
  # it), or {:error, why}.
  @spec vehicle(term(), %{integer() => info()}, :control | :link | :any, boolean()) ::
          {:ok, :free | {:stop_first, map()}} | {:error, String.t()}
  def vehicle(id, known, needs, force \\ false)

  def vehicle(id, known, needs, force) when is_integer(id) and id >= 0 do
    case Map.fetch(known, id) do
      :error ->
        {:error, unknown(id, known)}

      {:ok, info} ->
        cond do
          needs != :any and not info.mavlink? ->
            {:error, "vehicle #{id} is a fake vehicle of the test platform: it takes no MAVLink commands"}

          needs != :any and info.lost? ->
            {:error, "vehicle #{id} is lost (nothing heard for #{Format.duration(info.silent_ms || 0)}): nothing sent; check its link (vehicles())"}

          needs == :control and info.task != nil and not force ->
            {:error,
             "vehicle #{id} is flying task #{Format.task_label(info.task)} (run #{info.task.run}): nothing sent. " <>
               "Add force: true to stop that task first (the vehicle holds; the task's parent goes on as if it had completed)"}

          needs == :control and info.task != nil ->
            {:ok, {:stop_first, info.task}}

          true ->
            {:ok, :free}
        end
    end
  end

  def vehicle(other, _known, _needs, _force), do: {:error, "a vehicle is given by its system id (an integer, as vehicles() lists them), got: #{inspect(other)}"}

  defp unknown(id, known) when map_size(known) == 0,
    do: "no vehicle #{id}: no vehicle is known yet (is a link connected? see vehicles())"

  defp unknown(id, known), do: "no vehicle #{id}: the known vehicles are #{known |> Map.keys() |> Enum.sort() |> Enum.join(", ")} (see vehicles())"

  @doc false
  # A mode name: :guided, "GUIDED", "guided", :GUIDED -> :guided.
  @spec mode(term()) :: {:ok, atom()} | {:error, String.t()}
  def mode(mode) when is_atom(mode) and mode not in [nil, true, false], do: mode(Atom.to_string(mode))

  def mode(mode) when is_binary(mode) do
    name = mode |> String.trim() |> String.downcase()

    # Every mode's atom exists once the mode tables (Dolphin.Vehicles.Modes) are loaded.
    Code.ensure_loaded(Dolphin.Vehicles.Modes)

    if name =~ ~r/^[a-z][a-z0-9_]*$/ do
      {:ok, String.to_existing_atom(name)}
    else
      {:error, "a mode is a name such as :guided or \"BRAKE\", got: #{inspect(mode)}"}
    end
  rescue
    ArgumentError -> {:error, "no flight mode is called #{inspect(mode)}"}
  end

  def mode(other), do: {:error, "a mode is a name such as :guided or \"BRAKE\", got: #{inspect(other)}"}

  # ArduCopter modes flown by a pilot's sticks: without RC throttle the copter sinks.
  @pilot_modes [:stabilize, :acro, :alt_hold, :loiter, :poshold, :sport, :drift, :flowhold]

  @doc false
  # Refuses a pilot-controlled mode for a copter in the air (ARDUPILOT.md:
  # with no RC throttle it descends, lands and disarms) unless forced.
  @spec pilot_mode(atom(), boolean(), boolean()) :: :ok | {:error, String.t()}
  def pilot_mode(mode, in_air?, force) do
    if mode in @pilot_modes and in_air? and not force,
      do:
        {:error,
         "#{Format.mode(mode)} is flown by a pilot's sticks: with no RC throttle the copter sinks, lands and disarms. " <>
           "hold/1 holds position (BRAKE, else GUIDED); add force: true to set #{Format.mode(mode)} anyway"},
      else: :ok
  end

  @doc false
  @spec altitude(term()) :: {:ok, number()} | {:error, String.t()}
  def altitude(alt) when is_number(alt) and alt > 0 and alt <= 10_000, do: {:ok, alt}
  def altitude(alt), do: {:error, "an altitude is a number of metres above home, more than 0, got: #{inspect(alt)}"}

  @doc false
  @spec position(term(), term(), term()) :: {:ok, {number(), number(), number()}} | {:error, String.t()}
  def position(lat, lon, alt) do
    cond do
      not (is_number(lat) and lat >= -90 and lat <= 90) -> {:error, "latitude must be degrees in -90..90, got: #{inspect(lat)}"}
      not (is_number(lon) and lon >= -180 and lon <= 180) -> {:error, "longitude must be degrees in -180..180, got: #{inspect(lon)}"}
      not is_number(alt) -> {:error, "altitude must be a number of metres, got: #{inspect(alt)}"}
      true -> {:ok, {lat, lon, alt}}
    end
  end

  @doc false
  # A wait or a period in milliseconds.
  @spec ms(term(), atom()) :: {:ok, non_neg_integer()} | {:error, String.t()}
  def ms(n, _what) when is_integer(n) and n >= 0, do: {:ok, n}
  def ms(n, what), do: {:error, "#{what}: takes milliseconds (an integer, 0 or more), got: #{inspect(n)}"}

  @doc false
  @spec count(term()) :: {:ok, pos_integer()} | {:error, String.t()}
  def count(n) when is_integer(n) and n > 0, do: {:ok, n}
  def count(n), do: {:error, "a count is a positive integer, got: #{inspect(n)}"}

  @doc false
  # Keyword options of a helper: unknown keys are a mistake worth saying.
  @spec options(term(), [atom()]) :: {:ok, keyword()} | {:error, String.t()}
  def options(opts, allowed) do
    cond do
      not Keyword.keyword?(opts) ->
        {:error, "options are a keyword list (#{Enum.map_join(allowed, ", ", &"#{&1}: ...")}), got: #{inspect(opts)}"}

      (unknown = Keyword.keys(opts) -- allowed) != [] ->
        {:error, "unknown option#{if length(unknown) > 1, do: "s"} #{Enum.map_join(unknown, ", ", &inspect/1)}; options are #{Enum.map_join(allowed, ", ", &inspect/1)}"}

      true ->
        {:ok, opts}
    end
  end
end
