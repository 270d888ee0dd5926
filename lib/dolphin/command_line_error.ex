defmodule Dolphin.CommandLineError do
  @moduledoc """
  What a command-line tool (`mix dolphin.run`, `dolphin.check`,
  `dolphin.plan`, `dolphin.console`, ...) could not do, in the words it
  prints; the one error of every task's command line and start.

    * `reason` — `:usage` when the command line cannot be run as given (an
      unknown option, a bad value, no such file: exit status 2), `:failed`
      when the command line was right and the work failed (a port in use, a
      SITL binary that would not start, a transfer that failed: exit status 1);
    * `option` — the option that asked for what failed (`"--connect
      udpin:0.0.0.0:14550"`, `"--events"`), or nil;
    * `message` — what went wrong, in words; or `cause`, the error behind it
      (a `Dolphin.Link.EndpointError`, a `Dolphin.SITL.Error`, ...), whose
      message is then the text;
    * `usage` — the task's usage, printed after the message on its own line.

        iex> e = %Dolphin.CommandLineError{reason: :usage, message: "no command given", usage: "usage: mix dolphin.plan ..."}
        iex> Exception.message(e)
        "no command given\\nusage: mix dolphin.plan ..."
        iex> Exception.message(Dolphin.CommandLineError.failed("--connect udpin:0.0.0.0:14550", "address in use"))
        "--connect udpin:0.0.0.0:14550: address in use"
        iex> Exception.message(Dolphin.CommandLineError.failed(nil, %RuntimeError{message: "no SITL binary"}))
        "no SITL binary"
        iex> Dolphin.CommandLineError.exit_status(Dolphin.CommandLineError.failed(nil, "a port in use"))
        1
  """

  defexception reason: :failed, message: nil, option: nil, usage: nil, cause: nil

  @type t :: %__MODULE__{
          reason: :usage | :failed,
          message: String.t() | nil,
          option: String.t() | nil,
          usage: String.t() | nil,
          cause: Exception.t() | term()
        }

  @impl true
  def message(%__MODULE__{} = e) do
    text = e.message || describe(e.cause)
    text = if e.option, do: "#{e.option}: #{text}", else: text
    if e.usage, do: text <> "\n" <> e.usage, else: text
  end

  @doc "`{:error, e}`: a command line that cannot be run as given, saying why."
  @spec usage_error(String.t()) :: {:error, t()}
  def usage_error(message), do: {:error, %__MODULE__{reason: :usage, message: message}}

  @doc """
  The work asked for by `option` (or nil) failed; `why` is text, or the
  error behind it.
  """
  @spec failed(String.t() | nil, String.t() | term()) :: t()
  def failed(option, why) when is_binary(why), do: %__MODULE__{reason: :failed, option: option, message: why}
  def failed(option, why), do: %__MODULE__{reason: :failed, option: option, cause: why}

  @doc "The exit status of a task that ends with `e` (README.md, \"Exit status\")."
  @spec exit_status(t()) :: 1 | 2
  def exit_status(%__MODULE__{reason: :usage}), do: 2
  def exit_status(%__MODULE__{}), do: 1

  defp describe(%_{__exception__: true} = e), do: Exception.message(e)
  defp describe(text) when is_binary(text), do: text
  defp describe(other), do: inspect(other)
end
