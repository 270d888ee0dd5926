defmodule Dolphin.Test.Shell do
  @moduledoc """
  A command line run as a user types it in a shell (bash), in the project's
  directory with `MIX_ENV=test`: each `mix` of it a fresh VM, pipes and
  redirections as written. Bounded in time by coreutils' `timeout` (a hang
  is a failure, never a measure).

      %{out: out, err: err, statuses: [141, 0]} = Dolphin.Test.Shell.run("mix mavlink.decode x.tlog --tlog | head -1")
  """

  # Real seconds a command line may take on a loaded machine: generous.
  @bound_s 300

  @doc """
  Runs `line`; its standard output, its standard error and the exit status
  of each command of its (last) pipeline.
  """
  @spec run(String.t()) :: %{out: String.t(), err: String.t(), statuses: [non_neg_integer()]}
  def run(line) do
    dir = Path.join(System.tmp_dir!(), "dolphin-shell-#{System.unique_integer([:positive])}")
    File.mkdir_p!(dir)
    err = Path.join(dir, "err")
    statuses = Path.join(dir, "statuses")

    try do
      script = "exec 2>'#{err}'\n#{line}\necho \"${PIPESTATUS[*]}\" >'#{statuses}'\n"
      env = [{"MIX_ENV", "test"}, {"LANG", "C.UTF-8"}, {"LC_ALL", "C.UTF-8"}]
      {out, status} = System.cmd("timeout", ["--kill-after=10", "#{@bound_s}", "bash", "-c", script], cd: File.cwd!(), env: env)

      if status in [124, 137] and not File.exists?(statuses),
        do: raise(ExUnit.AssertionError, message: "#{inspect(line)} did not end within #{@bound_s} s:\n#{out}\n#{File.read!(err)}")

      codes = statuses |> File.read!() |> String.split() |> Enum.map(&String.to_integer/1)
      %{out: out, err: File.read!(err), statuses: codes}
    after
      File.rm_rf!(dir)
    end
  end

  @doc "A path or argument quoted for the shell."
  @spec quote(String.t()) :: String.t()
  def quote(text), do: "'" <> String.replace(text, "'", ~S('\'')) <> "'"
end
