defmodule Dolphin.Test.Timings do
  @moduledoc """
  An ExUnit formatter beside the usual one: where a part of the suite spent
  its time. For each test module, from its first test's start to its last
  test's end (wall clock, as it ran beside the others), the sum of its tests'
  own times and how many ran; written, longest first, to the file named by
  `DOLPHIN_TEST_TIMES` when the suite ends (`scripts/test` sets it for each
  part and prints the longest).

      module                                      wall_s  tests_s  tests  file

  Beside it, in the same name with `.failures` for `.txt`, one line per test
  that failed (its file and line, its name, and what went wrong, its lines
  joined, up to 600 characters), so that the last lines of a long log — all
  a CI report may keep — name every failure and say why.
  """
  use GenServer

  @doc "`formatters` (those ExUnit has), and this one when `DOLPHIN_TEST_TIMES` names a file."
  @spec formatters([module()]) :: [module()]
  def formatters(formatters) do
    case System.get_env("DOLPHIN_TEST_TIMES") do
      path when is_binary(path) and path != "" -> formatters ++ [__MODULE__]
      _ -> formatters
    end
  end

  @impl true
  def init(_opts), do: {:ok, %{path: System.fetch_env!("DOLPHIN_TEST_TIMES"), modules: %{}, failures: []}}

  @impl true
  def handle_cast({:module_started, %ExUnit.TestModule{name: name, file: file}}, s),
    do: {:noreply, put_in(s.modules[name], %{file: file, started: now(), finished: nil, tests_us: 0, tests: 0})}

  def handle_cast({:test_finished, %ExUnit.Test{module: module, time: time, state: state} = test}, s) when not is_tuple(state) or elem(state, 0) != :excluded do
    s = record_failure(s, test)

    case s.modules do
      %{^module => m} -> {:noreply, put_in(s.modules[module], %{m | tests_us: m.tests_us + time, tests: m.tests + 1})}
      _ -> {:noreply, s}
    end
  end

  def handle_cast({:module_finished, %ExUnit.TestModule{name: name}}, s) do
    case s.modules do
      %{^name => m} -> {:noreply, put_in(s.modules[name], %{m | finished: now()})}
      _ -> {:noreply, s}
    end
  end

  def handle_cast({:suite_finished, _times}, s) do
    write(s)
    {:noreply, s}
  end

  def handle_cast(_event, s), do: {:noreply, s}

  defp now, do: System.monotonic_time(:millisecond)

  defp record_failure(s, %ExUnit.Test{state: {:failed, [{kind, reason, stack} | _]}} = test),
    do: %{s | failures: [failure_line(test, what_went_wrong(kind, reason, stack)) | s.failures]}

  defp record_failure(s, %ExUnit.Test{state: {:invalid, _}} = test), do: %{s | failures: [failure_line(test, "its module's setup_all failed") | s.failures]}
  defp record_failure(s, _test), do: s

  defp failure_line(%ExUnit.Test{name: name, tags: tags}, what),
    do: "#{Path.relative_to_cwd(tags[:file] || "?")}:#{tags[:line]} #{name}: #{String.slice(what, 0, 600)}"

  defp what_went_wrong(:error, %ExUnit.AssertionError{message: message, expr: expr}, _stack) do
    if expr == ExUnit.AssertionError.no_value(),
      do: one_line(message),
      else: one_line(message) <> " " <> one_line(Macro.to_string(expr))
  end

  # ExUnit's advice on changing the timeout would fill the line: where the
  # test was waiting says more.
  defp what_went_wrong(:error, %ExUnit.TimeoutError{timeout: ms}, stack) do
    where = Enum.find_value(stack, fn {_m, _f, _a, at} -> if String.ends_with?(to_string(at[:file]), "_test.exs"), do: "#{at[:file]}:#{at[:line]}" end)
    "timed out after #{ms} ms" <> if(where, do: ", waiting at #{where}", else: "")
  end

  defp what_went_wrong(kind, reason, stack), do: one_line(Exception.format_banner(kind, reason, stack))

  # Lines joined with " | ", blank ones and indentation dropped.
  defp one_line(text), do: text |> String.split("\n", trim: true) |> Enum.map(&String.trim/1) |> Enum.reject(&(&1 == "")) |> Enum.join(" | ")

  defp write(%{path: path, modules: modules, failures: failures}) do
    rows =
      modules
      |> Enum.filter(fn {_, m} -> m.tests > 0 end)
      |> Enum.map(fn {name, m} -> {name, (m.finished || now()) - m.started, m} end)
      |> Enum.sort_by(fn {_, wall, _} -> -wall end)
      |> Enum.map(fn {name, wall, m} ->
        Enum.join(
          [
            String.pad_trailing(inspect(name), 52),
            String.pad_leading(:erlang.float_to_binary(wall / 1000, decimals: 1), 8),
            String.pad_leading(:erlang.float_to_binary(m.tests_us / 1_000_000, decimals: 1), 8),
            String.pad_leading(Integer.to_string(m.tests), 6),
            "  " <> Path.relative_to_cwd(m.file || "")
          ],
          ""
        )
      end)

    header = String.pad_trailing("module", 52) <> String.pad_leading("wall_s", 8) <> String.pad_leading("tests_s", 8) <> String.pad_leading("tests", 6) <> "  file"
    File.mkdir_p!(Path.dirname(path))
    File.write!(path, Enum.join([header | rows], "\n") <> "\n")
    File.write!(failures_path(path), Enum.map(Enum.reverse(failures), &[&1, "\n"]))
  end

  defp failures_path(path), do: Path.rootname(path) <> ".failures"
end
