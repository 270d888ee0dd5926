defmodule Dolphin.CLI.Values do
  @moduledoc """
  The values of the mix tasks' flags, read from the text given and checked
  for range and meaning before anything starts. A value that will not do is
  a `Dolphin.CommandLineError` of reason `:usage` (exit status 2) that names the flag, the value
  as given and what is allowed:

      iex> {:error, e} = Dolphin.CLI.Values.check([home: "250,400,0"], home: :location)
      iex> e.message
      "--home 250,400,0: the latitude 250 is not within -90..90 (LAT,LON,ALT: degrees, degrees, metres above mean sea level)"
      iex> Dolphin.CLI.Values.check([count: "3", quiet: true], count: :vehicles, quiet: :boolean)
      {:ok, [count: 3, quiet: true]}

  A task declares its options once, each with its kind, and parses with
  `switches/1` (what `OptionParser` is given: every value as text) and
  `check/2` (the values read). The kinds:

    * `:vehicles` — a number of vehicles, 1..254: each needs a system id of
      its own (1..254; 255 is the ground station's);
    * `:fleet_size` — a number of vehicles that may be spread over
      networks (`networks/3` checks that they fit): 1..#{254 * 64};
    * `{:range, first..last, rule}` — a whole number in the range (`rule`
      says what is allowed);
    * `:sysid` — a system id, 1..254;
    * `:vehicle_id` — a vehicle as `vehicles()` names it: a system id
      1..254, or `SYSID@NETWORK` for another vehicle with that system id
      (`Dolphin.Vehicles.Id`);
    * `:speedup` — a speed-up of the clock, 0.01..1000 (`Dolphin.Clock`'s
      limits: beyond 1000 the simulated vehicles cannot keep up);
    * `:location` — `LAT,LON,ALT`: latitude -90..90, longitude -180..180
      (degrees), altitude -1000..10000 m above mean sea level; a map
      `%{lat, lon, alt}`;
    * `:seconds` — a number of seconds, more than 0;
    * `:wait` — seconds of real time, more than 0 and at most 4294967
      (49.7 days, the longest a timer holds);
    * `:delay` — a number of seconds, 0 or more;
    * `:duration` — clock time as `mix dolphin.run --for` takes it (`90s`,
      `10m`, `1h`, `500ms`, a bare number is seconds), more than 0; in
      milliseconds;
    * `:metres`, `:speed` — a distance in metres, a speed in m/s, more than 0;
    * `:integer` — any whole number (a seed);
    * `:port` — a TCP port 0..65535 (0: a free one);
    * `:endpoint`, `{:endpoint, kinds}` — a link endpoint
      (`Dolphin.Link.Endpoint`) of one of `kinds` (default all), port
      1..65535; kept as text;
    * `{:one_of, %{"text" => value}}` — one of the words;
    * `:name` — text that is not empty;
    * `:output` — a file that can be written (`Dolphin.CLI.OutputFile`);
    * `{:file, what}` — a file to read, not a directory (whether it
      exists is for the task to find out when it reads it);
    * `:boolean`, `:string` — as `OptionParser` has them; `{:keep, kind}`
      (`:keep` for `{:keep, :string}`) — repeatable.
  """

  alias Dolphin.CommandLineError

  @type kind ::
          :vehicles
          | :fleet_size
          | {:range, Range.t(), String.t()}
          | :sysid
          | :vehicle_id
          | :speedup
          | :location
          | :seconds
          | :wait
          | :delay
          | :duration
          | :metres
          | :speed
          | :integer
          | :port
          | :endpoint
          | {:endpoint, [atom()]}
          | {:one_of, %{String.t() => term()}}
          | :name
          | :output
          | {:file, String.t()}
          | :boolean
          | :string

  @type spec :: [{atom(), kind() | :keep | {:keep, kind()}}]

  @max_sysid 254
  @max_networks 64
  @latitudes -90..90
  @longitudes -180..180
  @altitudes -1000..10_000
  @max_wait_s div(4_294_967_295, 1000)
  @location_form "LAT,LON,ALT: degrees, degrees, metres above mean sea level"

  @doc """
  The `strict:` switches of `OptionParser` for `spec`: booleans stay
  booleans, repeatable options `:keep`, every other value is read as text
  (by `check/2`).

      iex> Dolphin.CLI.Values.switches(count: :vehicles, camera: :boolean, connect: {:keep, :endpoint})
      [count: :string, camera: :boolean, connect: :keep]
  """
  @spec switches(spec()) :: keyword()
  def switches(spec) do
    Enum.map(spec, fn
      {key, :boolean} -> {key, :boolean}
      {key, :keep} -> {key, :keep}
      {key, {:keep, _}} -> {key, :keep}
      {key, _} -> {key, :string}
    end)
  end

  @doc """
  The options `OptionParser` read with `switches(spec)`, each value read
  and checked by its kind in `spec`, in order: `{:ok, opts}` with the
  values (options not in `spec` kept as they are), or the error of the
  first that will not do.
  """
  @spec check(keyword(), spec()) :: {:ok, keyword()} | {:error, CommandLineError.t()}
  def check(opts, spec) do
    Enum.reduce_while(opts, {:ok, []}, fn {key, given}, {:ok, acc} ->
      kind =
        case Keyword.get(spec, key, :string) do
          :keep -> :string
          {:keep, kind} -> kind
          kind -> kind
        end

      case value(kind, given) do
        {:ok, value} -> {:cont, {:ok, [{key, value} | acc]}}
        {:error, rule} -> {:halt, CommandLineError.usage_error("#{flag(key)} #{shown(given)}: #{rule}")}
      end
    end)
    |> case do
      {:ok, acc} -> {:ok, Enum.reverse(acc)}
      error -> error
    end
  end

  @doc """
  The system ids of `count` vehicles from `first`, or the error that they
  do not fit in 1..254 (`count_flag` and `first_flag` name where they came
  from).

      iex> Dolphin.CLI.Values.sysids(3, 10, "--count", "--first-sysid")
      {:ok, 10..12}
      iex> {:error, e} = Dolphin.CLI.Values.sysids(3, 253, "--count", "--first-sysid")
      iex> e.message
      "--count 3 with --first-sysid 253: system ids 253..255 do not fit in 1..254 (255 is the ground station's)"
  """
  @spec sysids(pos_integer(), pos_integer(), String.t(), String.t()) :: {:ok, Range.t()} | {:error, CommandLineError.t()}
  def sysids(count, first, count_flag, first_flag) do
    last = first + count - 1

    if last <= @max_sysid,
      do: {:ok, first..last},
      else: CommandLineError.usage_error("#{count_flag} #{count} with #{first_flag} #{first}: system ids #{first}..#{last} do not fit in 1..#{@max_sysid} (255 is the ground station's)")
  end

  @doc """
  The system ids on each network of `count` vehicles spread evenly over
  `networks` networks, each numbered from `first`; the error says why
  they do not fit in 1..254 (`--count`, `--networks` and `--first-sysid`
  named).

      iex> Dolphin.CLI.Values.networks(2000, 8, 1)
      {:ok, 1..250}
      iex> {:error, e} = Dolphin.CLI.Values.networks(300, 1, 1)
      iex> e.message
      "--count 300: a network holds 254 vehicles at most (system ids 1..254, 255 is the ground station's): --networks spreads more over several"
      iex> {:error, e} = Dolphin.CLI.Values.networks(2000, 4, 1)
      iex> e.message
      "--count 2000 over --networks 4: 500 vehicles a network, system ids 1..500, do not fit in 1..254 (255 is the ground station's)"
  """
  @spec networks(pos_integer(), pos_integer(), pos_integer()) :: {:ok, Range.t()} | {:error, CommandLineError.t()}
  def networks(count, 1, first) when first + count - 1 > @max_sysid and first == 1,
    do:
      CommandLineError.usage_error("--count #{count}: a network holds #{@max_sysid} vehicles at most (system ids 1..#{@max_sysid}, 255 is the ground station's): --networks spreads more over several")

  def networks(count, 1, first), do: sysids(count, first, "--count", "--first-sysid")

  def networks(count, networks, _first) when count < networks,
    do: CommandLineError.usage_error("--networks #{networks} for --count #{count}: each network needs a vehicle at least")

  def networks(count, networks, first) do
    per = div(count + networks - 1, networks)
    last = first + per - 1

    if last <= @max_sysid,
      do: {:ok, first..last},
      else:
        CommandLineError.usage_error(
          "--count #{count} over --networks #{networks}#{if first != 1, do: " with --first-sysid #{first}"}: #{per} vehicles a network, system ids #{first}..#{last}, do not fit in 1..#{@max_sysid} (255 is the ground station's)"
        )
  end

  @doc """
  The script or input file `path` (what it is: `"script"`, `"plan file"`,
  ...) is a file that exists, or the error that says what it is instead.

      iex> {:error, e} = Dolphin.CLI.Values.input_file("lib", "script")
      iex> e.message
      "lib is a directory, not a script"
      iex> {:error, e} = Dolphin.CLI.Values.input_file("nope.exs", "script")
      iex> e.message
      "no such script: nope.exs"
  """
  @spec input_file(Path.t(), String.t()) :: :ok | {:error, CommandLineError.t()}
  def input_file(path, what) do
    case file_problem(path, what) do
      nil -> :ok
      problem -> CommandLineError.usage_error(problem)
    end
  end

  @doc """
  What is wrong with `path` as a `what` to read (`nil`: nothing): it does
  not exist, or it is a directory or something else than a file.

      iex> Dolphin.CLI.Values.file_problem("lib", "plan file")
      "lib is a directory, not a plan file"
  """
  @spec file_problem(Path.t(), String.t()) :: String.t() | nil
  def file_problem(path, what) do
    case File.stat(path) do
      {:ok, %File.Stat{type: :regular}} -> nil
      {:ok, %File.Stat{type: :directory}} -> "#{path} is a directory, not a #{what}"
      {:ok, %File.Stat{}} -> "#{path} is not a file: it cannot be read as a #{what}"
      {:error, :enoent} -> "no such #{what}: #{path}"
      {:error, why} -> "cannot read #{path}: #{:file.format_error(why)}"
    end
  end

  @doc """
  Parses the command line of a task that takes one script and `switches`
  (`OptionParser`'s `strict:`): `{:ok, file, opts}` for `check.(file, opts)`
  to judge further (it returns `{:ok, file, opts}` or an error), else the
  error of no script, two scripts or an unknown option.

      iex> {:error, e} = Dolphin.CLI.Values.parse_script(["--bogus"], [quiet: :boolean], &{:ok, &1, &2})
      iex> e.message
      "bad option --bogus"
  """
  @spec parse_script([String.t()], keyword(), (Path.t(), keyword() -> {:ok, Path.t(), keyword()} | {:error, CommandLineError.t()})) ::
          {:ok, Path.t(), keyword()} | {:error, CommandLineError.t()}
  def parse_script(argv, switches, check) do
    case OptionParser.parse(argv, strict: switches) do
      {opts, [file], []} -> check.(file, opts)
      {_, [], []} -> CommandLineError.usage_error("no script given")
      {_, [_, extra | _], []} -> CommandLineError.usage_error("one script at a time (unexpected #{inspect(extra)})")
      {_, _, [{switch, value} | _]} -> CommandLineError.usage_error("bad option #{switch}#{if value, do: " " <> value, else: ""}")
    end
  end

  @doc """
  A command line of options only (no arguments), parsed with `options`
  and checked (`check/2`), then given to `more` for the task's own rules;
  an argument or an unknown option is bad usage, saying which
  (`unexpected` words an argument: `fn arg -> text end`).
  """
  @spec parse_options([String.t()], spec(), (keyword() -> {:ok, keyword()} | {:error, CommandLineError.t()}), (String.t() -> String.t())) ::
          {:ok, keyword()} | {:error, CommandLineError.t()}
  def parse_options(argv, options, more \\ &{:ok, &1}, unexpected \\ &"unexpected argument #{inspect(&1)}") do
    case OptionParser.parse(argv, strict: switches(options)) do
      {opts, [], []} -> with {:ok, opts} <- check(opts, options), do: more.(opts)
      {_, [arg | _], []} -> CommandLineError.usage_error(unexpected.(arg))
      {_, _, [{switch, value} | _]} -> CommandLineError.usage_error("bad option #{switch}#{if value, do: " " <> value, else: ""}")
    end
  end

  @doc """
  The options of every command that brings a fleet up (`mix dolphin.run`,
  `mix dolphin.console`): its links, simulated or SITL vehicles, the
  speed-up, the telemetry log and where to forward it.
  """
  @spec fleet_options() :: keyword()
  def fleet_options do
    [
      connect: {:keep, :endpoint},
      sim: :sim_fleet,
      sitl: :sitl_fleet,
      sitl_bin: {:file, "SITL binary"},
      sitl_defaults: {:keep, {:file, "parameter file"}},
      fleet: {:file, "fleet file"},
      world: {:file, "world file"},
      home: :home,
      seed: :integer,
      speedup: :speedup,
      tlog: :output,
      forward: {:keep, {:endpoint, [:udpout]}}
    ]
  end

  @doc """
  `--world FILE` goes with `--sim` or `--sitl` (SITL's sensors are a
  sidecar's, `Dolphin.Sim.Sidecar`): nothing else senses it (the file
  itself is read as the vehicles start: `Dolphin.CLI.Vehicles`).
  """
  @spec world(keyword()) :: :ok | {:error, CommandLineError.t()}
  def world(opts) do
    if opts[:world] != nil and opts[:sim] == nil and opts[:sitl] == nil,
      do: CommandLineError.usage_error("--world is what simulated sensors sense: it goes with --sim or --sitl"),
      else: :ok
  end

  # --- kinds ------------------------------------------------------------------

  defp value(:boolean, given), do: {:ok, given}
  defp value(:string, given), do: {:ok, given}

  # Where simulated or SITL vehicles start: "LAT,LON" or "LAT,LON,ALT" (metres above sea level).
  defp value(:home, text) do
    numbers = for part <- String.split(text, ","), do: number(String.trim(part))

    place =
      case numbers do
        [{:ok, lat}, {:ok, lon}] -> {lat, lon, 0.0}
        [{:ok, lat}, {:ok, lon}, {:ok, alt}] -> {lat, lon, alt}
        _ -> nil
      end

    case place do
      {lat, lon, _alt} when lat >= -90 and lat <= 90 and lon >= -180 and lon <= 180 ->
        {:ok, place}

      _ ->
        {:error, "a place as LAT,LON or LAT,LON,ALT (degrees, latitude -90..90, longitude -180..180; metres above sea level)"}
    end
  end

  # N copters, or airframes and counts: "copter:2,plane:1,boat:1,sub:3".
  # The simulator's fleet may be several networks (Dolphin.Sim.Local); SITL's is one.
  defp value(:sim_fleet, text), do: fleet_spec(text, Dolphin.Sim.airframes(), Dolphin.Sim.Companion.models(), :fleet_size)
  defp value(:sitl_fleet, text), do: fleet_spec(text, Dolphin.SITL.airframes(), Dolphin.Sim.Companion.models(), :vehicles)

  defp value(:vehicles, text), do: integer(text, 1..@max_sysid, "a number of vehicles from 1 to #{@max_sysid} (each needs a system id of its own)")

  defp value(:fleet_size, text),
    do: integer(text, 1..(@max_sysid * @max_networks), "a number of vehicles from 1 to #{@max_sysid * @max_networks} (#{@max_sysid} a network, each with a system id of its own there)")

  defp value({:range, range, rule}, text), do: integer(text, range, rule)
  defp value(:sysid, text), do: integer(text, 1..@max_sysid, "a system id from 1 to #{@max_sysid} (255 is the ground station's)")

  defp value(:vehicle_id, text) do
    if String.contains?(text, "@") do
      with :error <- Dolphin.Vehicles.Id.parse(text), do: {:error, "a system id from 1 to #{@max_sysid}, or SYSID@NETWORK as vehicles() lists it"}
    else
      value(:sysid, text)
    end
  end

  defp value(:integer, text) do
    case Integer.parse(text) do
      {n, ""} -> {:ok, n}
      _ -> {:error, "a whole number"}
    end
  end

  defp value(:port, text), do: integer(text, 0..65_535, "a TCP port from 1 to 65535 (0: any free one)")

  defp value(:speedup, text) do
    rule = "a number from 0.01 to #{Dolphin.Clock.max_speedup()} (beyond #{Dolphin.Clock.max_speedup()} the simulated vehicles cannot keep up with the clock)"

    case number(text) do
      {:ok, k} -> if Dolphin.Clock.speedup?(k), do: {:ok, k}, else: {:error, rule}
      :error -> {:error, rule}
    end
  end

  defp value(:seconds, text), do: positive(text, "a number of seconds, more than 0")
  defp value(:metres, text), do: positive(text, "a number of metres, more than 0")
  defp value(:speed, text), do: positive(text, "a speed in metres per second, more than 0")

  defp value(:wait, text) do
    rule = "a number of seconds, more than 0 and at most #{@max_wait_s} (49.7 days, the longest a timer holds)"

    case number(text) do
      {:ok, s} when s > 0 and s <= @max_wait_s -> {:ok, s}
      _ -> {:error, rule}
    end
  end

  defp value(:delay, text) do
    case number(text) do
      {:ok, s} when s >= 0 -> {:ok, s}
      _ -> {:error, "a number of seconds, 0 or more"}
    end
  end

  defp value(:duration, text) do
    rule = "a duration more than 0 such as 90s, 10m, 1h or 500ms (a bare number is seconds)"
    units = %{"" => 1000, "s" => 1000, "ms" => 1, "m" => 60_000, "min" => 60_000, "h" => 3_600_000}

    case Float.parse(text) do
      {n, unit} when is_map_key(units, unit) and n > 0 ->
        ms = round(n * units[unit])
        if ms > 0, do: {:ok, ms}, else: {:error, rule}

      _ ->
        {:error, rule}
    end
  end

  defp value(:location, text) do
    with [_, _, _] = parts <- Enum.map(String.split(text, ","), &String.trim/1),
         [{:ok, lat}, {:ok, lon}, {:ok, alt}] <- Enum.map(parts, &number/1) do
      [lat_text, lon_text, alt_text] = parts

      cond do
        not within?(lat, @latitudes) -> {:error, "the latitude #{lat_text} is not within #{range(@latitudes)} (#{@location_form})"}
        not within?(lon, @longitudes) -> {:error, "the longitude #{lon_text} is not within #{range(@longitudes)} (#{@location_form})"}
        not within?(alt, @altitudes) -> {:error, "the altitude #{alt_text} m is not within #{range(@altitudes)} (#{@location_form})"}
        true -> {:ok, %{lat: lat, lon: lon, alt: alt}}
      end
    else
      _ -> {:error, "#{@location_form}, e.g. 40.444233,-7.375234,820"}
    end
  end

  defp value(:endpoint, text), do: value({:endpoint, [:udpin, :udpout, :tcp]}, text)

  defp value({:endpoint, kinds}, text) do
    allowed = Enum.map_join(kinds, " or ", &"#{&1}:HOST:PORT")

    case Dolphin.Link.Endpoint.parse(text) do
      {:ok, %{port: 0}} ->
        {:error, "the port is 1..65535"}

      {:ok, %{kind: kind}} ->
        if kind in kinds, do: {:ok, text}, else: {:error, "#{allowed} here, not #{kind}"}

      {:error, %{reason: :bad_port, detail: port}} ->
        {:error, "the port #{shown(port)} is not within 1..65535"}

      {:error, %{reason: :unknown_kind, detail: kind}} ->
        {:error, "unknown kind #{shown(kind)}: #{allowed}"}

      {:error, %{reason: :no_host}} ->
        {:error, "no host: #{allowed}"}

      {:error, %{reason: :unresolved, detail: host}} ->
        {:error, "the host #{shown(host)} does not resolve to an address"}

      {:error, _} ->
        {:error, "#{allowed}, e.g. #{hd(kinds)}:#{if hd(kinds) == :udpin, do: "0.0.0.0", else: "127.0.0.1"}:14550"}
    end
  end

  defp value({:one_of, words}, text) do
    case Map.fetch(words, text) do
      {:ok, value} -> {:ok, value}
      :error -> {:error, words |> Map.keys() |> Enum.sort() |> then(fn ws -> Enum.join(Enum.drop(ws, -1), ", ") <> " or " <> List.last(ws) end)}
    end
  end

  defp value(:name, text), do: if(String.trim(text) == "", do: {:error, "a name that is not empty"}, else: {:ok, text})

  defp value(:output, path) do
    case Dolphin.CLI.OutputFile.problem(path) do
      nil -> {:ok, path}
      problem -> {:error, problem}
    end
  end

  defp value({:file, what}, path) do
    if File.dir?(path), do: {:error, "a directory, not a #{what}"}, else: {:ok, path}
  end

  # "copter:2,boat:1": airframes and counts; a simulated group may carry
  # sensors, "copter:2+smoke+range" (and "2+smoke": N copters with them).
  defp fleet_spec(text, airframes, sensors, size) do
    if String.contains?(text, [":", "+"]), do: groups(text, airframes, sensors, size), else: value(size, text)
  end

  defp groups(text, airframes, sensors, size) do
    max = if size == :fleet_size, do: @max_sysid * @max_networks, else: @max_sysid
    known = Enum.map(airframes, &Atom.to_string/1)
    models = Enum.map(sensors, &Atom.to_string/1)

    fleet =
      for part <- String.split(text, ",", trim: true) do
        [group | carried] = String.split(part, "+")

        with {:ok, airframe, n} <- group(group, known, size),
             {:ok, carried} <- carried(carried, models) do
          if carried == [], do: {airframe, n}, else: {airframe, n, carried}
        end
      end

    rule =
      "a number of copters, or airframes and counts such as #{Enum.at(known, -2)}:1,#{List.last(known)}:3 (airframes: #{Enum.join(known, ", ")}; #{max} vehicles at most)" <>
        if(sensors == [], do: "", else: "; sensors after +, as copter:2+smoke (#{Enum.join(models, ", ")})")

    case Enum.find(fleet, &match?({:error, _}, &1)) do
      {:error, {:sensor, name}} -> {:error, "no simulated sensor #{inspect(name)}: the simulator's sensors are #{Enum.join(models, ", ")}"}
      {:error, _} -> {:error, rule}
      nil -> if Enum.sum(Enum.map(fleet, &elem(&1, 1))) <= max, do: {:ok, fleet}, else: {:error, rule}
    end
  end

  defp group(text, known, size) do
    case String.split(text, ":") do
      [n] ->
        with {:ok, n} <- value(size, n), do: {:ok, :copter, n}, else: (_ -> {:error, :group})

      [name, n] ->
        with true <- name in known, {:ok, count} <- value(size, n), do: {:ok, String.to_existing_atom(name), count}, else: (_ -> {:error, :group})

      _ ->
        {:error, :group}
    end
  end

  defp carried([], _models), do: {:ok, []}
  defp carried(_names, []), do: {:error, :group}

  defp carried(names, models) do
    case Enum.find(names, &(&1 not in models)) do
      nil -> {:ok, names |> Enum.uniq() |> Enum.map(&String.to_existing_atom/1)}
      name -> {:error, {:sensor, name}}
    end
  end

  defp integer(text, range, rule) do
    case Integer.parse(text) do
      {n, ""} -> if n in range, do: {:ok, n}, else: {:error, rule}
      _ -> {:error, rule}
    end
  end

  defp positive(text, rule) do
    case number(text) do
      {:ok, x} when x > 0 -> {:ok, x}
      _ -> {:error, rule}
    end
  end

  # Numbers as the user types them: 5, 5.0, .5, 1e3, -2 (no "inf" or "nan").
  defp number(text) do
    text = if String.starts_with?(text, "."), do: "0" <> text, else: String.replace_prefix(text, "-.", "-0.")

    case Float.parse(text) do
      {x, ""} -> {:ok, x}
      _ -> :error
    end
  end

  defp within?(x, first..last), do: x >= first and x <= last
  defp range(first..last), do: "#{first}..#{last}"

  # A flag as the user types it.
  defp flag(key), do: "--" <> String.replace(Atom.to_string(key), "_", "-")

  # The value as given; quoted when it would not read as one word.
  defp shown(text) when is_binary(text), do: if(text == "" or String.match?(text, ~r/\s/), do: inspect(text), else: text)
  defp shown(other), do: inspect(other)
end
