defmodule Mix.Tasks.Dolphin.Param do
  @shortdoc "Reads, sets, lists, saves and loads a vehicle's parameters"

  @moduledoc """
  A vehicle's parameters, with the MAVLink parameter protocol
  (`Dolphin.Vehicles.ParamProtocol`, `Dolphin.Vehicles.ParamList`):

      mix dolphin.param get WPNAV_SPEED --connect udpin:0.0.0.0:14550
      mix dolphin.param set WPNAV_SPEED 800 --connect udpin:0.0.0.0:14550 [--vehicle 2]
      mix dolphin.param list [FILTER] --connect udpin:0.0.0.0:14550
      mix dolphin.param save copter.parm --connect udpin:0.0.0.0:14550
      mix dolphin.param load copter.parm --connect udpin:0.0.0.0:14550

  `get` prints one value, typed as the vehicle says (an integer for the
  integer types); `set` sets it and reads it back, and says the value the
  vehicle keeps; `list` prints every parameter (or those whose name
  contains FILTER), fetched whole: on a lossy link the missing ones are
  asked for again by index, never the whole list again; `save` writes them
  as ArduPilot's parameter files are written (`NAME VALUE` a line, the
  format of `--defaults` and of MAVProxy's `param save`); `load` sets every
  parameter of such a file (`#` comments; a comma or tabs between name and
  value are taken too) and says which were set, refused or unknown.

  A name the vehicle does not have is said with the names near (`vehicle 1
  has no parameter WPNAV_SPED (did you mean WPNAV_SPEED?)`); a value it
  keeps otherwise (a whole number for an integer type) with the value kept.

  ## Options

    * `--connect ENDPOINT` — the link to the vehicle (`udpin:HOST:PORT`,
      `udpout:HOST:PORT`, `tcp:HOST:PORT`), required
    * `--vehicle ID` — which vehicle (a system id, or `SYSID@NETWORK`),
      needed when more than one is heard
    * `--timeout SECONDS` — how long to wait for the vehicle to be heard
      and booted (default 10)

  ## Exit status

  As every task's (README.md, "Exit status"): 0 — done; 1 — the vehicle
  was not heard, did not answer, has no such parameter, kept another value,
  or a file could not be read or written (a line of a file to load that is
  not `NAME VALUE` is named); 2 — bad usage.
  """

  use Mix.Task

  alias Dolphin.CLI.Values
  alias Dolphin.{CommandLineError, Vehicles}
  alias Dolphin.Vehicles.ParamProtocol

  @options [connect: :endpoint, vehicle: :vehicle_id, timeout: :wait]

  @usage """
  usage: mix dolphin.param get NAME --connect ENDPOINT [--vehicle ID] [--timeout SECONDS]
         mix dolphin.param set NAME VALUE --connect ENDPOINT [--vehicle ID] [--timeout SECONDS]
         mix dolphin.param list [FILTER] --connect ENDPOINT [--vehicle ID] [--timeout SECONDS]
         mix dolphin.param save FILE --connect ENDPOINT [--vehicle ID] [--timeout SECONDS]
         mix dolphin.param load FILE --connect ENDPOINT [--vehicle ID] [--timeout SECONDS]\
  """

  @impl Mix.Task
  def run(argv) do
    Dolphin.CLI.Signals.exit_on_signal("dolphin.param", "stopped before it finished")
    Dolphin.CLI.Stdout.watch()
    Mix.Task.run("app.start")

    case main(argv) do
      {:ok, text} -> Mix.shell().info(text)
      {:error, e} -> Mix.raise("mix dolphin.param: " <> Exception.message(e), exit_status: CommandLineError.exit_status(e))
    end
  end

  @doc "Does the work of the task: `{:ok, text to print}` or `{:error, %Dolphin.CommandLineError{}}`."
  @spec main([String.t()]) :: {:ok, String.t()} | {:error, CommandLineError.t()}
  def main(argv) do
    case OptionParser.parse(argv, strict: Values.switches(@options)) do
      {opts, args, []} ->
        with {:ok, opts} <- Values.check(opts, @options),
             {:ok, verb} <- verb(args) do
          case Dolphin.CLI.OneVehicle.with_vehicle("dolphin.param", opts, &verb.(&1)) do
            {:ok, text} -> {:ok, text}
            {:error, {:usage, text}} -> usage(text)
            {:error, %CommandLineError{} = e} -> {:error, e}
            {:error, why} -> {:error, CommandLineError.failed(nil, why)}
          end
        end

      {_, _, [{switch, value} | _]} ->
        usage("bad option #{switch}#{if value, do: " " <> value, else: ""}")
    end
  end

  defp usage(text), do: {:error, %CommandLineError{reason: :usage, message: text, usage: @usage}}

  # What each verb does to the vehicle, checked before the link is opened.
  defp verb(["get", name]), do: {:ok, &get(&1, name)}

  defp verb(["set", name, value]) do
    case Float.parse(value) do
      {number, ""} -> {:ok, &set(&1, name, if(number == trunc(number) and not String.contains?(value, "."), do: trunc(number), else: number))}
      _ -> usage("set #{name} #{value}: the value is a number")
    end
  end

  defp verb(["list"]), do: {:ok, &list(&1, "")}
  defp verb(["list", filter]), do: {:ok, &list(&1, filter)}
  defp verb(["save", file]), do: with(:ok <- writable(file), do: {:ok, &save(&1, file)})
  defp verb(["load", file]), do: with({:ok, params} <- read_file(file), do: {:ok, &load(&1, file, params)})
  defp verb([]), do: usage("what to do: get, set, list, save or load")
  defp verb([other | _]) when other in ["get", "set", "list", "save", "load"], do: usage("#{other}: wrong arguments")
  defp verb([other | _]), do: usage("unknown command #{inspect(other)}: get, set, list, save or load")

  defp get(id, name) do
    case Vehicles.param(id, name, nil, []) do
      {:ok, value} -> {:ok, "vehicle #{id}: #{name} = #{ParamProtocol.show(value)}"}
      {:error, e} -> {:error, CommandLineError.failed(nil, e)}
    end
  end

  defp set(id, name, value) do
    case Vehicles.param(id, name, value, []) do
      {:ok, kept} -> {:ok, "vehicle #{id}: #{name} set to #{ParamProtocol.show(kept)}"}
      {:error, e} -> {:error, CommandLineError.failed(nil, e)}
    end
  end

  defp list(id, filter) do
    with {:ok, all} <- fetch(id) do
      shown = Enum.filter(all, &String.contains?(&1.name, filter))
      {:ok, Enum.join(ParamProtocol.listing(shown) ++ ["vehicle #{id}: #{length(shown)} of #{length(all)} parameters"], "\n")}
    end
  end

  defp save(id, file) do
    with {:ok, all} <- fetch(id) do
      text = ["# parameters of vehicle #{id}, read by mix dolphin.param\n" | Enum.map(all, &"#{&1.name} #{ParamProtocol.show(&1.value)}\n")]

      case File.write(file, text) do
        :ok -> {:ok, "vehicle #{id}: saved #{length(all)} parameters to #{file}"}
        {:error, why} -> {:error, CommandLineError.failed(nil, "cannot write #{file}: #{:file.format_error(why)}")}
      end
    end
  end

  # The vehicle's list first: a name it does not have is said at once,
  # with the names near, not after the retries of a set nobody answers.
  defp load(id, file, params) do
    with {:ok, all} <- fetch(id) do
      names = Enum.map(all, & &1.name)

      results =
        for {name, value, _line} <- params do
          if name in names,
            do: {name, value, Vehicles.param(id, name, value, [])},
            else: {name, value, {:error, Vehicles.unknown_param(id, name, names)}}
        end

      loaded(id, file, results)
    end
  end

  defp loaded(id, file, results) do
    failed = for {_name, _value, {:error, e}} <- results, do: Exception.message(e)
    set = length(results) - length(failed)

    if failed == [],
      do: {:ok, "vehicle #{id}: set #{set} parameters from #{file}"},
      else: {:error, CommandLineError.failed(nil, "set #{set} of #{length(results)} parameters from #{file}; not set:\n  " <> Enum.join(failed, "\n  "))}
  end

  defp fetch(id) do
    case Vehicles.param_list(id) do
      {:ok, all} -> {:ok, all}
      {:error, e} -> {:error, CommandLineError.failed(nil, e)}
    end
  end

  defp writable(file) do
    dir = Path.dirname(file)

    cond do
      File.dir?(file) -> usage("save #{file}: a directory, not a file")
      not File.dir?(dir) -> usage("save #{file}: no directory #{dir}")
      true -> :ok
    end
  end

  @doc false
  # A parameter file's lines as {name, value, line}, or the first line that is not one.
  @spec read_file(Path.t()) :: {:ok, [{String.t(), number(), pos_integer()}]} | {:error, CommandLineError.t()}
  def read_file(file) do
    case File.read(file) do
      {:ok, text} -> parse(text, file)
      {:error, :enoent} -> usage("load #{file}: no such file")
      {:error, why} -> {:error, CommandLineError.failed(nil, "cannot read #{file}: #{:file.format_error(why)}")}
    end
  end

  defp parse(text, file) do
    text
    |> String.split("\n")
    |> Enum.with_index(1)
    |> Enum.reduce_while({:ok, []}, fn {line, n}, {:ok, acc} ->
      case line |> String.split("#", parts: 2) |> hd() |> String.trim() do
        "" ->
          {:cont, {:ok, acc}}

        content ->
          case String.split(content, [" ", "\t", ","], trim: true) do
            [name, value] when byte_size(name) <= 16 ->
              case Float.parse(value) do
                {number, ""} -> {:cont, {:ok, [{name, if(String.contains?(value, ".") or String.contains?(value, "e"), do: number, else: trunc(number)), n} | acc]}}
                _ -> {:halt, {:error, CommandLineError.failed(nil, "#{file}:#{n}: #{inspect(value)} is not a number (NAME VALUE a line)")}}
              end

            _ ->
              {:halt, {:error, CommandLineError.failed(nil, "#{file}:#{n}: not NAME VALUE: #{inspect(content)}")}}
          end
      end
    end)
    |> case do
      {:ok, params} -> {:ok, Enum.reverse(params)}
      error -> error
    end
  end
end
