defmodule Dolphin.CLI.OutputFile do
  @moduledoc """
  The files a command writes (`--tlog`, `--events`, `--report`, `-o`, a
  plan's `OUT.plan`), checked when its command line is read: a file that
  cannot be written is bad usage, said with the option that names it, before
  anything is started or flies (not half-way through a run, or after a
  transfer).

      iex> Dolphin.CLI.OutputFile.check("--tlog", "/no/such/dir/run.tlog")
      {:error, "--tlog /no/such/dir/run.tlog: cannot create it: no such directory /no/such/dir"}
      iex> Dolphin.CLI.OutputFile.check("--report", "/")
      {:error, "--report /: it is a directory, not a file"}

  A telemetry log given by name replaces the file that was there
  (`replace/1`), as the events file and the report do: a log holds one run.
  """

  @doc """
  `:ok` when `path` can be written (created, or written over), else what
  stands in the way, after `option` and the path. Nothing is left behind:
  a file that did not exist still does not.
  """
  @spec check(String.t(), Path.t()) :: :ok | {:error, String.t()}
  def check(option, path) do
    case problem(path) do
      nil -> :ok
      problem -> {:error, "#{option} #{path}: #{problem}"}
    end
  end

  @doc """
  What stands in the way of writing `path`, in words, or nil (see
  `check/2`, which says it after the option that names the file).

      iex> Dolphin.CLI.OutputFile.problem("/")
      "it is a directory, not a file"
  """
  @spec problem(Path.t()) :: String.t() | nil
  def problem(path) do
    dir = Path.dirname(path)

    cond do
      File.dir?(path) -> "it is a directory, not a file"
      File.exists?(path) -> writable(path)
      not File.exists?(dir) -> "cannot create it: no such directory #{dir}"
      not File.dir?(dir) -> "cannot create it: #{dir} is not a directory"
      true -> creatable(path)
    end
  end

  @doc """
  Empties `path` for a new run (creating it if need be): `{:ok, :replaced}`
  when a file was there, `{:ok, :created}` when not.
  """
  @spec replace(Path.t()) :: {:ok, :created | :replaced} | {:error, String.t()}
  def replace(path) do
    existed = File.exists?(path)

    case File.write(path, "") do
      :ok -> {:ok, if(existed, do: :replaced, else: :created)}
      {:error, why} -> {:error, "cannot write #{path}: #{:file.format_error(why)}"}
    end
  end

  @doc """
  Empties the telemetry log of `--tlog` for a new run, console or station
  session (`replace/1`): the line that says so (`telemetry log: PATH`, and
  whether it replaces a file), or the failure, naming the option.
  """
  @spec start_log(Path.t()) :: {:ok, String.t()} | {:error, Dolphin.CommandLineError.t()}
  def start_log(path) do
    case replace(path) do
      {:ok, how} -> {:ok, "telemetry log: #{path}" <> if(how == :replaced, do: " (replaces the file that was there)", else: "")}
      {:error, why} -> {:error, Dolphin.CommandLineError.failed("--tlog", why)}
    end
  end

  # Opened for appending and closed again: its content stays as it is.
  defp writable(path) do
    case File.open(path, [:append]) do
      {:ok, io} ->
        File.close(io)
        nil

      {:error, why} ->
        "cannot write it: #{:file.format_error(why)}"
    end
  end

  # Permissions are the file system's to judge (and root's differ): try.
  defp creatable(path) do
    case File.open(path, [:write, :exclusive]) do
      {:ok, io} ->
        File.close(io)
        File.rm(path)
        nil

      {:error, why} ->
        "cannot create it: #{:file.format_error(why)}"
    end
  end
end
