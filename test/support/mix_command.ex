defmodule Dolphin.Test.MixCommand do
  @moduledoc """
  A `mix` command run the way a user runs it: its own OS process, a fresh
  VM (`mix` execs it: the process id is the VM's), MIX_ENV=test, output and
  exit status read through a port. Whatever is left of it when the test
  ends is killed.

      port = Dolphin.Test.MixCommand.start(["dolphin.run", script, "--fake", "1"])
      Dolphin.Test.MixCommand.wait_for(port, ~r/started on vehicle 1/)
      Dolphin.Test.MixCommand.kill(port, "TERM")
      output = Dolphin.Test.MixCommand.wait_exit(port, 143)

  The output read so far is kept in the test process (`output/0`); terminal
  escapes and carriage returns are taken out of it.
  """

  import ExUnit.Assertions

  # Real ms any one step of a command may take on a loaded machine (a VM
  # boot, a vehicle arming at speed-up 10): generous, never a measurement.
  @step 120_000

  @doc "Starts `mix args` (`env`: more variables, as `{name, value}` strings)."
  def start(args, env \\ []), do: open([System.find_executable("mix") | args], env)

  @doc "Starts the executable `exe` with `args`, as `start/2` does `mix`."
  def open([exe | args], env \\ []) do
    env = Enum.map([{"MIX_ENV", "test"}, {"LANG", "C.UTF-8"}, {"LC_ALL", "C.UTF-8"}, {"TERM", "xterm"}] ++ env, fn {k, v} -> {String.to_charlist(k), String.to_charlist(v)} end)
    port = Port.open({:spawn_executable, exe}, [:binary, :exit_status, :stderr_to_stdout, args: args, cd: File.cwd!(), env: env])
    Process.put(:mix_command_output, "")
    kill_on_exit(port)
    port
  end

  @doc """
  Whatever is left of the OS process behind `port` when the test ends (a
  failed test): it and its descendants are killed, by process id.
  """
  def kill_on_exit(port) do
    {:os_pid, os_pid} = Port.info(port, :os_pid)

    ExUnit.Callbacks.on_exit(fn ->
      for pid <- descendants(os_pid) ++ [os_pid], do: System.cmd("kill", ["-9", Integer.to_string(pid)], stderr_to_stdout: true)
    end)
  end

  @doc """
  Runs each `mix` command line at once, each in its own OS process, and
  returns their exit statuses and outputs (standard output and error), in
  order: `[{status, output}]`.
  """
  def run_all(commands, env \\ []) do
    ports = Enum.map(commands, &start(&1, env))
    Enum.map(Enum.zip(commands, ports), fn {args, port} -> collect_all(port, args, "") end)
  end

  defp collect_all(port, args, output) do
    receive do
      {^port, {:data, data}} -> collect_all(port, args, output <> clean(data))
      {^port, {:exit_status, status}} -> {status, output}
    after
      @step -> flunk("mix #{Enum.join(args, " ")} did not end within #{@step} ms:\n#{output}")
    end
  end

  @doc "The process id of the command (its VM)."
  def os_pid(port) do
    {:os_pid, os_pid} = Port.info(port, :os_pid)
    os_pid
  end

  @doc "Sends the signal (`\"TERM\"`, `\"INT\"`) to the command."
  def kill(port, signal) do
    {_, 0} = System.cmd("kill", ["-#{signal}", Integer.to_string(os_pid(port))])
    :ok
  end

  @doc """
  Sends the signals one right after the other, as `kill -TERM $pid; kill
  -TERM $pid` in a shell does (no process started between them). The first
  must reach the command; the second finds nothing to signal when the first
  has already ended it (a run with nothing to hold stops in a few
  milliseconds, and a loaded machine may run the shell's second `kill`
  later than that).
  """
  def kill_twice(port, first, second) do
    pid = Integer.to_string(os_pid(port))
    {_, 0} = System.cmd("sh", ["-c", "kill -#{first} #{pid} && { kill -#{second} #{pid} 2>/dev/null; true; }"])
    :ok
  end

  @doc "The output read so far."
  def output, do: Process.get(:mix_command_output, "")

  @doc "Waits (bounded) until the output matches `pattern`."
  def wait_for(port, pattern) do
    unless output() =~ pattern do
      receive do
        {^port, {:data, data}} ->
          Process.put(:mix_command_output, output() <> clean(data))
          wait_for(port, pattern)

        {^port, {:exit_status, status}} ->
          flunk("the command ended (status #{status}) before #{inspect(pattern)}:\n#{output()}")
      after
        @step -> flunk("no #{inspect(pattern)} within #{@step} ms:\n#{output()}")
      end
    end
  end

  @doc "Waits (bounded) for the command's end; asserts its exit status; returns its whole output."
  def wait_exit(port, expected) do
    receive do
      {^port, {:data, data}} ->
        Process.put(:mix_command_output, output() <> clean(data))
        wait_exit(port, expected)

      {^port, {:exit_status, status}} ->
        assert status == expected, "exit status #{status}, expected #{expected}:\n#{output()}"
        output()
    after
      @step -> flunk("the command did not end within #{@step} ms:\n#{output()}")
    end
  end

  @doc "Runs `mix args` to its end; `{output, exit status}`."
  def run(args, env \\ []), do: collect(start(args, env))

  defp collect(port) do
    receive do
      {^port, {:data, data}} ->
        Process.put(:mix_command_output, output() <> clean(data))
        collect(port)

      {^port, {:exit_status, status}} ->
        {output(), status}
    after
      @step -> flunk("the command did not end within #{@step} ms:\n#{output()}")
    end
  end

  defp descendants(pid) do
    case System.cmd("ps", ["-o", "pid=", "--ppid", Integer.to_string(pid)], stderr_to_stdout: true) do
      {out, 0} -> out |> String.split() |> Enum.map(&String.to_integer/1) |> Enum.flat_map(&(descendants(&1) ++ [&1]))
      _ -> []
    end
  end

  # Without terminal escapes and carriage returns.
  defp clean(data), do: data |> String.replace(~r/\e\[[0-9;?]*[A-Za-z]/, "") |> String.replace("\r", "")
end
