defmodule Dolphin.CLI.UsageError do
  @moduledoc """
  A command line that cannot be run as given: an unknown option, a bad value,
  no script or no such file. `mix dolphin.run` prints it with its usage and
  exits with status 2.

      iex> Exception.message(%Dolphin.CLI.UsageError{message: "no script given"})
      "no script given"
  """

  defexception [:message]

  @type t :: %__MODULE__{message: String.t()}

  @doc """
  Parses the command line of a task that takes one script and `switches`
  (`OptionParser`'s `strict:`): `{:ok, file, opts}` for `check.(file, opts)`
  to judge further (it returns `{:ok, file, opts}` or an error), else the
  error of no script, two scripts or an unknown option.

      iex> {:error, e} = Dolphin.CLI.UsageError.parse_script(["--bogus"], [quiet: :boolean], &{:ok, &1, &2})
      iex> e.message
      "bad option --bogus"
  """
  @spec parse_script([String.t()], keyword(), (Path.t(), keyword() -> {:ok, Path.t(), keyword()} | {:error, t()})) ::
          {:ok, Path.t(), keyword()} | {:error, t()}
  def parse_script(argv, switches, check) do
    case OptionParser.parse(argv, strict: switches) do
      {opts, [file], []} -> check.(file, opts)
      {_, [], []} -> error("no script given")
      {_, [_, extra | _], []} -> error("one script at a time (unexpected #{inspect(extra)})")
      {_, _, [{switch, value} | _]} -> error("bad option #{switch}#{if value, do: " " <> value, else: ""}")
    end
  end

  @doc "`{:error, %Dolphin.CLI.UsageError{}}` with `message`."
  @spec error(String.t()) :: {:error, t()}
  def error(message), do: {:error, %__MODULE__{message: message}}
end
