defmodule Mix.Tasks.Dolphin.Plan do
  @shortdoc "Moves missions to and from QGroundControl .plan files"

  @moduledoc """
  Moves missions between Dolphin scripts and QGroundControl plan files
  (`.plan`; see `Dolphin.Mission.Plan` for the format and what survives).

      mix dolphin.plan list examples/single_vehicle.exs
      mix dolphin.plan export examples/single_vehicle.exs "Survey Area" survey.plan
      mix dolphin.plan export examples/single_vehicle.exs simple_mission survey.plan
      mix dolphin.plan import survey.plan
      mix dolphin.plan import survey.plan --items

  ## export FILE NAME OUT.plan

  Writes the mission `NAME` of `FILE` to `OUT.plan`. `FILE` is a Dolphin
  script (`use Dolphin.Script`) or a file of missions (`mission "..." do
  ... end` blocks, with or without `use Dolphin.Script`). The mission is
  found **without running the script**: its top-level definitions are
  evaluated in order — assignments, `use`/`import`/`alias`/`require`,
  `defmodule`, bare `mission` blocks — and everything else is skipped, as is
  any assignment that calls a statement of the language that acts (`pick`,
  `execute`, `forever`, `message`, `ask`, ...). So a mission defined at the
  top of a script, from locations and values defined there, is found; one
  built inside `forever do ... end` is not. (The definitions are ordinary
  code: export only files you would run.)

  `NAME` is the mission's name (`mission "Survey Area" do`) or the variable
  it is bound to (`simple_mission`). `list` shows the candidates.

  Options: `--home LAT,LON,ALT` — the home (degrees, metres above mean sea
  level) of a mission that has none (else its first absolute position is
  taken); `--cruise-speed M_S`, `--hover-speed M_S` — the plan's speeds
  (default 15 and 5 m/s).

  ## import IN.plan

  Prints the plan's mission as the Elixir source of a script's `mission`
  block — each item as the command that gives it back exactly, else a raw
  `item` — ready to paste into a script. Options: `--items` prints the
  `MISSION_ITEM_INT`s instead; `--name NAME` names the mission (default: the
  file's base name). QGroundControl's complex items (its own surveys,
  corridor scans) are not read: save the plan with them converted to
  simple waypoints.

  ## list FILE

  The missions `FILE` defines, as `export` finds them, and the statements
  it skipped.

  Errors (a missing file, no such mission, a malformed plan) stop the task
  with a message and a non-zero exit status.
  """

  use Mix.Task

  alias Dolphin.Console.{Format, MissionFile, MissionSource}
  alias Dolphin.Mission

  @switches [home: :string, cruise_speed: :float, hover_speed: :float, items: :boolean, name: :string]

  @usage """
  usage: mix dolphin.plan export FILE NAME OUT.plan [--home LAT,LON,ALT] [--cruise-speed M_S] [--hover-speed M_S]
         mix dolphin.plan import IN.plan [--items] [--name NAME]
         mix dolphin.plan list FILE\
  """

  @impl Mix.Task
  def run(argv) do
    Mix.Task.run("app.config")

    case main(argv) do
      {:ok, text} -> Mix.shell().info(text)
      {:error, message} -> Mix.raise("mix dolphin.plan: " <> message)
    end
  end

  @doc """
  Does the work of the task: `{:ok, text to print}` or `{:error, message}`
  (the usage is part of the message of a usage error).
  """
  @spec main([String.t()]) :: {:ok, String.t()} | {:error, String.t()}
  def main(argv) do
    case OptionParser.parse(argv, strict: @switches) do
      {opts, args, []} -> command(args, opts)
      {_, _, [{switch, value} | _]} -> usage("bad option #{switch}#{if value, do: " " <> value, else: ""}")
    end
  end

  defp usage(message), do: {:error, message <> "\n" <> @usage}

  defp command(["export", file, name, out], opts) do
    with :ok <- only(opts, [:home, :cruise_speed, :hover_speed], "export"),
         {:ok, plan_opts} <- plan_opts(opts),
         {:ok, found, notes} <- MissionFile.read(file),
         {:ok, %{mission: mission} = one} <- pick(found, name, notes),
         {:ok, json} <- encode(mission, plan_opts),
         :ok <- write(out, json) do
      count = length(Mission.to_items(mission, Keyword.take(plan_opts, [:home]))) - 1
      {:ok, "wrote #{out}: mission #{MissionFile.label(one)}, #{count} item#{if count != 1, do: "s"} after home (QGroundControl: Plan, Open)"}
    end
  end

  defp command(["import", file], opts) do
    with :ok <- only(opts, [:items, :name], "import"),
         {:ok, json} <- read(file),
         {:ok, mission} <- decode(json, opts[:name] || Path.basename(file, ".plan"), file) do
      if opts[:items],
        do: {:ok, Format.items(Mission.to_items(mission))},
        else: {:ok, "# #{Path.basename(file)}: #{length(mission.commands)} commands\n" <> MissionSource.to_source(mission)}
    end
  end

  defp command(["list", file], opts) do
    with :ok <- only(opts, [], "list"),
         {:ok, found, notes} <- MissionFile.read(file) do
      missions =
        case found do
          [] -> ["no missions"]
          found -> Enum.map(found, &"#{MissionFile.label(&1)}: #{items(&1.mission)}")
        end

      {:ok, Enum.join(missions ++ notes, "\n")}
    end
  end

  defp command([verb | _] = args, _opts) when verb in ["export", "import", "list"],
    do: usage("#{verb}: wrong arguments #{inspect(args)}")

  defp command([], _opts), do: usage("no command given")
  defp command([verb | _], _opts), do: usage("unknown command #{inspect(verb)} (export, import or list)")

  defp items(mission) do
    n = length(Mission.to_items(mission)) - 1
    "#{n} item#{if n != 1, do: "s"} after home"
  rescue
    e in ArgumentError -> "cannot be made into items: " <> Exception.message(e)
  end

  defp only(opts, allowed, verb) do
    case Keyword.keys(opts) -- allowed do
      [] -> :ok
      [key | _] -> usage("--#{String.replace(Atom.to_string(key), "_", "-")} is no option of #{verb}")
    end
  end

  defp plan_opts(opts) do
    speeds = Enum.filter([cruise_speed: opts[:cruise_speed], hover_speed: opts[:hover_speed]], fn {_, v} -> v != nil end)

    cond do
      Enum.any?(speeds, fn {_, v} -> v <= 0 end) ->
        {:error, "speeds must be positive"}

      home = opts[:home] ->
        case home(home) do
          {:ok, location} -> {:ok, [home: location] ++ speeds}
          :error -> usage("--home takes LAT,LON,ALT (degrees, degrees, metres above mean sea level), got #{inspect(home)}")
        end

      true ->
        {:ok, speeds}
    end
  end

  @doc """
  A home position from `LAT,LON,ALT`.

      iex> Mix.Tasks.Dolphin.Plan.home("40.444233,-7.375234,820")
      {:ok, %Dolphin.Geo.Location{lat: 40.444233, lon: -7.375234, h: 820.0}}
      iex> Mix.Tasks.Dolphin.Plan.home("40.4,north")
      :error
  """
  @spec home(String.t()) :: {:ok, Dolphin.Geo.Location.t()} | :error
  def home(text) do
    with [lat, lon, alt] <- String.split(text, ",", trim: true),
         {lat, ""} <- Float.parse(String.trim(lat)),
         {lon, ""} <- Float.parse(String.trim(lon)),
         {alt, ""} <- Float.parse(String.trim(alt)),
         true <- abs(lat) <= 90 and abs(lon) <= 180 do
      {:ok, Dolphin.Geo.location(lat, lon, alt)}
    else
      _ -> :error
    end
  end

  defp pick(found, name, notes) do
    case MissionFile.pick(found, name) do
      {:ok, one} -> {:ok, one}
      {:error, why} -> {:error, Enum.join([why | notes], "\n")}
    end
  end

  defp encode(mission, opts) do
    {:ok, Mission.to_plan(mission, opts)}
  rescue
    e in ArgumentError -> {:error, "mission #{inspect(mission.name)}: #{Exception.message(e)} (--home supplies a home)"}
  end

  defp write(path, json) do
    case File.write(path, json) do
      :ok -> :ok
      {:error, why} -> {:error, "cannot write #{path}: #{:file.format_error(why)}"}
    end
  end

  defp read(path) do
    case File.read(path) do
      {:ok, text} -> {:ok, text}
      {:error, why} -> {:error, "cannot read #{path}: #{:file.format_error(why)}"}
    end
  end

  defp decode(json, name, file) do
    case Mission.from_plan(json, name: name) do
      {:ok, mission} -> {:ok, mission}
      {:error, e} -> {:error, "#{file}: #{Exception.message(e)}"}
    end
  end
end
