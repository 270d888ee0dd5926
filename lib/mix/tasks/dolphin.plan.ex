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

  ## upload IN.plan --connect ENDPOINT [--vehicle ID] [--timeout SECONDS]

  Uploads the plan's mission to a vehicle and reads it back to compare: what
  a mission task does before it flies, as a command. `ENDPOINT` is a link as
  `mix dolphin.run --connect` takes it (`udpin:0.0.0.0:14550`,
  `udpout:HOST:PORT`, `tcp:HOST:PORT`); the vehicle is `--vehicle ID`, or the
  only one heard within `--timeout` seconds (default 10). Prints the time each
  transfer took and its retransmissions (items and requests sent again on a
  lossy link), and whether the vehicle holds exactly the mission:

      $ mix dolphin.plan upload survey.plan --connect udpin:0.0.0.0:14550
      vehicle 1: uploaded 14 items in 0.21 s (0 retransmissions); read back in 0.05 s (0 retransmissions): the vehicle holds exactly the mission

  ## download OUT.plan --connect ENDPOINT [--vehicle ID] [--timeout SECONDS]

  Reads a vehicle's mission and writes it as a plan (its item 0 is the
  plan's home).

  ## list FILE

  The missions `FILE` defines, as `export` finds them, and the statements
  it skipped.

  ## Exit status

  As every task's (README.md, "Exit status"): 1 — no such mission, a
  malformed plan, a link that cannot be opened (a port in use), no vehicle
  heard, a transfer that failed; 2 — bad usage (an unknown command or
  option, wrong arguments, a value out of range, a bad endpoint, no such
  file or a directory given for it: the message names the flag, the value
  and what is allowed); 130 / 143 — Ctrl-C / SIGTERM stopped it. The
  message says what went wrong. `--home` takes latitude -90..90, longitude
  -180..180 and altitude -1000..10000 m; speeds, `--timeout` more than 0;
  `--vehicle` a system id 1..254, or `SYSID@NETWORK` for another vehicle
  with that system id (as the run's `vehicles()` names it).
  """

  use Mix.Task

  alias Dolphin.CLI.Values
  alias Dolphin.CommandLineError
  alias Dolphin.Console.{Format, MissionFile, MissionSource}
  alias Dolphin.Mission

  @options [home: :location, cruise_speed: :speed, hover_speed: :speed, items: :boolean, name: :name, connect: :endpoint, vehicle: :vehicle_id, timeout: :wait]

  @usage """
  usage: mix dolphin.plan export FILE NAME OUT.plan [--home LAT,LON,ALT] [--cruise-speed M_S] [--hover-speed M_S]
         mix dolphin.plan import IN.plan [--items] [--name NAME]
         mix dolphin.plan list FILE
         mix dolphin.plan upload IN.plan --connect ENDPOINT [--vehicle ID] [--timeout SECONDS]
         mix dolphin.plan download OUT.plan --connect ENDPOINT [--vehicle ID] [--timeout SECONDS]\
  """

  @impl Mix.Task
  def run(argv) do
    verb = List.first(argv)
    # A transfer cut short has nothing of ours to undo but its link, which ends with the VM.
    Dolphin.CLI.Signals.exit_on_signal("dolphin.plan", if(verb in ["upload", "download"], do: "the #{verb} did not finish", else: "stopped before it finished"))
    # A closed pipe (`| head`) ends the task at once, quietly.
    Dolphin.CLI.Stdout.watch()

    Mix.Task.run("app.config")
    # Transfers need the links and vehicles of the application.
    if verb in ["upload", "download"], do: Mix.Task.run("app.start")

    case main(argv) do
      {:ok, text} -> Mix.shell().info(text)
      {:error, error} -> Mix.raise("mix dolphin.plan: " <> Exception.message(error), exit_status: if(error.reason == :usage, do: 2, else: 1))
    end
  end

  @doc """
  Does the work of the task: `{:ok, text to print}` or
  `{:error, %Dolphin.CommandLineError{}}` (the usage is part of the message of
  a usage error).
  """
  @spec main([String.t()]) :: {:ok, String.t()} | {:error, CommandLineError.t()}
  def main(argv) do
    result =
      case OptionParser.parse(argv, strict: Values.switches(@options)) do
        {opts, args, []} ->
          case Values.check(opts, @options) do
            {:ok, opts} -> args |> command(opts) |> missing_input(args)
            {:error, e} -> usage(Exception.message(e))
          end

        {_, _, [{switch, value} | _]} ->
          usage("bad option #{switch}#{if value, do: " " <> value, else: ""}")
      end

    case result do
      {:error, {:usage, message}} -> {:error, %CommandLineError{reason: :usage, message: message, usage: @usage}}
      {:error, message} when is_binary(message) -> {:error, %CommandLineError{reason: :failed, message: message}}
      {:error, %{__exception__: true} = e} -> {:error, %CommandLineError{reason: :failed, message: Exception.message(e), cause: e}}
      {:ok, text} -> {:ok, text}
    end
  end

  # The steps below say what went wrong in words; main/1 makes the error of them.
  defp usage(message), do: {:error, {:usage, message}}

  # A failure because the file to read is not there (or is a directory): the
  # command line named the wrong one, bad usage (README.md, "Exit status").
  defp missing_input({:error, why} = error, args) when is_binary(why) or is_exception(why) do
    file =
      case args do
        ["export", file, _name, _out] -> file
        [verb, file] when verb in ["import", "list", "upload"] -> file
        _ -> nil
      end

    if file && not File.regular?(file), do: usage(if(is_binary(why), do: why, else: Exception.message(why))), else: error
  end

  defp missing_input(result, _args), do: result

  defp command(["export", file, name, out], opts) do
    with :ok <- only(opts, [:home, :cruise_speed, :hover_speed], "export"),
         :ok <- writable("export", out),
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

  defp command(["upload", file], opts) do
    with :ok <- only(opts, [:connect, :vehicle, :timeout], "upload"),
         {:ok, json} <- read(file),
         {:ok, mission} <- decode(json, Path.basename(file, ".plan"), file) do
      with_vehicle(opts, fn id -> upload(id, Mission.to_items(mission)) end)
    end
  end

  defp command(["download", out], opts) do
    # Before the transfer: a plan that could not be written would waste it.
    with :ok <- only(opts, [:connect, :vehicle, :timeout], "download"),
         :ok <- writable("download", out) do
      with_vehicle(opts, fn id -> download(id, out) end)
    end
  end

  defp command([verb | _] = args, _opts) when verb in ["export", "import", "list", "upload", "download"],
    do: usage("#{verb}: wrong arguments #{inspect(args)}")

  defp command([], _opts), do: usage("no command given")
  defp command([verb | _], _opts), do: usage("unknown command #{inspect(verb)} (export, import, list, upload or download)")

  # --- transfers ---------------------------------------------------------------

  defp with_vehicle(opts, fun) do
    case Dolphin.CLI.OneVehicle.with_vehicle("dolphin.plan", opts, fun) do
      {:error, {:usage, message}} -> usage(message)
      other -> other
    end
  end

  defp upload(id, items) do
    {up_ms, up} = timed(fn -> Dolphin.Vehicles.upload_mission(id, items, progress_to: self()) end)
    up_done = done(:upload)
    unconfirmed? = match?({:error, %Dolphin.MissionError{result: :unconfirmed}}, up)

    if up == :ok or unconfirmed? do
      {down_ms, down} = timed(fn -> Dolphin.Vehicles.download_mission(id, progress_to: self()) end)
      down_done = done(:download)
      what = "vehicle #{id}: uploaded #{length(items)} items in #{seconds(up_ms)} (#{retransmissions(up_done)})"
      lost_ack = if unconfirmed?, do: ", its final MISSION_ACK lost", else: ""
      read = "read back in #{seconds(down_ms)} (#{retransmissions(down_done)})"

      case down do
        {:ok, back} ->
          case Mission.compare_download(items, back) do
            :ok -> {:ok, "#{what}#{lost_ack}; #{read}: the vehicle holds exactly the mission"}
            {:error, e} -> {:error, "#{what}#{lost_ack}; #{read}, but it differs: #{Exception.message(e)}"}
          end

        {:error, e} ->
          {:error, "#{what}#{lost_ack}; reading it back failed: #{Exception.message(e)}"}
      end
    else
      {:error, e} = up
      {:error, "upload failed after #{seconds(up_ms)} (#{retransmissions(up_done)}): #{Exception.message(e)}"}
    end
  end

  defp download(id, out) do
    {ms, result} = timed(fn -> Dolphin.Vehicles.download_mission(id, progress_to: self()) end)
    took = "in #{seconds(ms)} (#{retransmissions(done(:download))})"

    with {:ok, items} <- result,
         {:ok, mission} <- from_items(items, id, Path.basename(out, ".plan")),
         :ok <- write(out, Mission.to_plan(mission)) do
      {:ok, "vehicle #{id}: downloaded #{length(items)} items #{took}; wrote #{out}"}
    else
      {:error, %Dolphin.MissionError{} = e} -> {:error, "download failed #{took}: #{Exception.message(e)}"}
      {:error, message} -> {:error, message}
    end
  end

  defp from_items([], id, _name), do: {:error, "vehicle #{id} holds no mission (not even home): nothing to write"}

  defp from_items(items, id, name) do
    case MissionSource.from_items(items, name) do
      {:ok, mission} -> {:ok, mission}
      {:error, e} -> {:error, "vehicle #{id}'s mission cannot be written as a plan: #{Exception.message(e)}"}
    end
  end

  defp timed(fun) do
    start = System.monotonic_time(:millisecond)
    result = fun.()
    {System.monotonic_time(:millisecond) - start, result}
  end

  # What the protocol reported at the end of a transfer (it went to this process).
  defp done(operation) do
    receive do
      {:mission_done, ^operation, report} -> flush_progress(report)
    after
      0 -> flush_progress(%{retransmissions: 0})
    end
  end

  defp flush_progress(report) do
    receive do
      {:mission_progress, _, _, _} -> flush_progress(report)
    after
      0 -> report
    end
  end

  defp seconds(ms), do: "#{:erlang.float_to_binary(ms / 1000, decimals: 2)} s"
  defp retransmissions(%{retransmissions: 1}), do: "1 retransmission"
  defp retransmissions(%{retransmissions: n}), do: "#{n} retransmissions"

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
    speeds = Keyword.take(opts, [:cruise_speed, :hover_speed])

    case opts[:home] do
      nil -> {:ok, speeds}
      %{lat: lat, lon: lon, alt: alt} -> {:ok, [home: Dolphin.Geo.location(lat, lon, alt)] ++ speeds}
    end
  end

  defp pick(found, name, notes) do
    case MissionFile.pick(found, name) do
      {:ok, one} -> {:ok, one}
      {:error, e} -> {:error, Enum.join([Exception.message(e) | notes], "\n")}
    end
  end

  defp encode(mission, opts) do
    {:ok, Mission.to_plan(mission, opts)}
  rescue
    e in ArgumentError ->
      what = Exception.message(e)
      what = if String.starts_with?(what, "mission #{inspect(mission.name)}"), do: what, else: "mission #{inspect(mission.name)}: #{what}"
      {:error, if(mission.home == nil and opts[:home] == nil, do: what <> ", or give the plan one with --home LAT,LON,ALT", else: what)}
  end

  defp writable(verb, out) do
    case Dolphin.CLI.OutputFile.check(verb, out) do
      :ok -> :ok
      {:error, message} -> usage(message)
    end
  end

  defp write(path, json) do
    case File.write(path, json) do
      :ok -> :ok
      {:error, why} -> {:error, "cannot write #{path}: #{:file.format_error(why)}"}
    end
  end

  defp read(path) do
    with nil <- Values.file_problem(path, "plan file"),
         {:ok, text} <- File.read(path) do
      {:ok, text}
    else
      {:error, why} -> {:error, "cannot read #{path}: #{:file.format_error(why)}"}
      problem -> {:error, problem}
    end
  end

  defp decode(json, name, file) do
    case Mission.from_plan(json, name: name) do
      {:ok, mission} -> {:ok, mission}
      {:error, e} -> {:error, "#{file}: #{Exception.message(e)}"}
    end
  end
end
