# Another OS process a benchmark runs beside it (a simulator, a feed),
# shared by the benchmarks that start one (Code.require_file'd by them).
defmodule Bench.OSProcess do
  @doc "CPU milliseconds of an OS process (user + system), from /proc."
  def cpu_ms(pid) do
    [utime, stime] = File.read!("/proc/#{pid}/stat") |> String.split(" ") |> Enum.slice(13, 2) |> Enum.map(&String.to_integer/1)
    (utime + stime) * 10
  end

  @doc "Lines of the process's output (a port opened with `{:line, _}`), as they come, until `pattern` matches one."
  def await_line(port, pattern, timeout_ms) do
    receive do
      {^port, {:data, {:eol, line}}} -> if line =~ pattern, do: line, else: await_line(port, pattern, timeout_ms)
      {^port, {:data, {:noeol, _}}} -> await_line(port, pattern, timeout_ms)
      {^port, {:exit_status, status}} -> raise "the process exited (#{status}) before printing #{inspect(pattern)}"
    after
      timeout_ms -> raise "the process printed no #{inspect(pattern)} within #{timeout_ms} ms"
    end
  end
end
