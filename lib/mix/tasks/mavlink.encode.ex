defmodule Mix.Tasks.Mavlink.Encode do
  @shortdoc "Encodes JSON message records into MAVLink frames (one hex frame per line)"

  @moduledoc """
  Reads JSON lines in the record format of `Dolphin.MAVLink.Record` (as
  `mix mavlink.decode` prints them) and prints each message's frame in hex, one
  per line. The header comes from `mavlink`, `sysid`, `compid` and `seq`; a
  record with `"signed": true` is signed with its `signing` (`secret_key`,
  `link_id`, `timestamp`). A `frame` key, if present, is ignored.

      mix mavlink.encode messages.jsonl
      mix mavlink.decode capture.bin | mix mavlink.encode -

  `FILE` may be `-` for standard input. Blank lines are skipped. A line that
  cannot be encoded is reported on standard error with its line number, and the
  task exits with status 1 after the whole file (as every task's exit
  status, README.md, "Exit status": 2 — bad usage, such as no such file).
  Piped into a reader that stops early (`| head -2`), it ends at once and
  quietly, with status 141 (`Dolphin.CLI.Stdout`).
  """

  use Mix.Task

  alias Dolphin.MAVLink.{Frame, Record}

  @impl Mix.Task
  def run(args) do
    Dolphin.CLI.Signals.exit_on_signal("mavlink.encode", "stopped before the end of the input")
    # A closed pipe (`| head`) ends the task at once, quietly.
    Dolphin.CLI.Stdout.watch()

    case OptionParser.parse(args, strict: []) do
      {_, [file], []} ->
        lines = if file == "-", do: IO.stream(:stdio, :line), else: stream!(file)

        case encode(lines, :stdio) do
          [] -> :ok
          errors -> Mix.raise("mavlink.encode: #{length(errors)} line(s) of #{file} could not be encoded")
        end

      _ ->
        Mix.raise("usage: mix mavlink.encode FILE", exit_status: 2)
    end
  end

  defp stream!(path) do
    # No such file, or a directory: bad usage (README.md, "Exit status").
    case Dolphin.CLI.Values.file_problem(path, "file of JSON records") do
      nil -> File.stream!(path)
      problem -> Mix.raise("mavlink.encode: #{problem}", exit_status: 2)
    end
  end

  @doc """
  Encodes every record of `lines`, writing hex frames to `output`; returns the
  errors as `{line_number, reason}` (also written to standard error).
  """
  @spec encode(Enumerable.t(), IO.device(), module()) :: [{pos_integer(), String.t()}]
  def encode(lines, output, dialect \\ Dolphin.MAVLink.default_dialect()) do
    lines
    |> Stream.with_index(1)
    |> Enum.reduce([], fn {line, n}, errors ->
      line = String.trim(line)

      if line == "" do
        errors
      else
        case encode_line(line, dialect) do
          {:ok, hex} ->
            IO.binwrite(output, [hex, ?\n])
            errors

          {:error, why} ->
            IO.puts(:stderr, "line #{n}: #{why}")
            [{n, why} | errors]
        end
      end
    end)
    |> Enum.reverse()
  end

  defp encode_line(line, dialect) do
    case Record.decode(line, dialect) do
      {:ok, message, opts} -> {:ok, Base.encode16(Frame.encode(message, opts), case: :lower)}
      {:error, e} -> {:error, Exception.message(e)}
    end
  rescue
    e in ArgumentError -> {:error, Exception.message(e)}
  end
end
