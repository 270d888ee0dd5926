defmodule Dolphin.Script.Error do
  @moduledoc """
  Why a script could not be compiled or did not complete: `kind` is
  `:syntax`, `:compile`, `:failed` (a task or the code failed), `:halted`
  (the script called `halt/1`); `file` and `line` say where in the script.
  """
  defexception [:kind, :file, :line, :column, :message, :reason]

  @type t :: %__MODULE__{
          kind: :syntax | :compile | :failed | :halted,
          file: String.t() | nil,
          line: pos_integer() | nil,
          column: pos_integer() | nil,
          message: String.t(),
          reason: term()
        }

  @doc "`file:line: message` (`file:line:column:` for a syntax error)"
  @spec format(t()) :: String.t()
  def format(%__MODULE__{file: file, line: line, column: column, message: message}) do
    where = Enum.reject([file && Path.relative_to_cwd(file), line, line && column], &is_nil/1) |> Enum.join(":")
    if where == "", do: message, else: "#{where}: #{message}"
  end
end
