defmodule Dolphin.Docs.LanguageTest do
  # Every example of docs/language.md runs, as a user runs it:
  # `mix dolphin.run FILE ARGS` on fake vehicles or the simulator. Each
  # ```elixir block is preceded by a marker saying how:
  #
  #   <!-- run: --fake 2 | status 1 | prints "text" -->   run it, check its exit status (default 0)
  #                                                      and that its output holds each text
  #   <!-- compile -->                                    compile it only (long flights)
  #
  # A block without a marker is a mistake: examples that are never run rot.
  # Its own Dolphin.Instance (its vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.Test.GroundStation
  alias Mix.Tasks.Dolphin.Run

  @moduletag :tmp_dir
  @moduletag timeout: 300_000

  @doc_path Path.expand("../../docs/language.md", __DIR__)
  @external_resource @doc_path

  # [{line, marker, code}] of every ```elixir block, in order.
  defp blocks(text) do
    lines = String.split(text, "\n")

    {blocks, _} =
      lines
      |> Enum.with_index(1)
      |> Enum.reduce({[], nil}, fn
        {"```elixir", n}, {acc, nil} -> {acc, {n, marker(Enum.at(lines, n - 2)), []}}
        {"```", _n}, {acc, {n, marker, code}} -> {[{n, marker, Enum.join(Enum.reverse(code), "\n") <> "\n"} | acc], nil}
        {line, _n}, {acc, {n, marker, code}} -> {acc, {n, marker, [line | code]}}
        _, state -> state
      end)

    Enum.reverse(blocks)
  end

  defp marker("<!-- compile -->"), do: :compile

  defp marker("<!-- run: " <> rest) do
    [args | checks] = rest |> String.trim_trailing(" -->") |> String.split(" | ")

    Enum.reduce(checks, %{args: OptionParser.split(args), status: 0, prints: []}, fn
      "status " <> n, m -> %{m | status: String.to_integer(n)}
      "prints " <> text, m -> %{m | prints: m.prints ++ [text |> String.trim("\"")]}
    end)
  end

  defp marker(_), do: nil

  defp run_script(path, args) do
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    code = Run.main([path | args] ++ ["--no-tlog"], out: out, err: err)
    GroundStation.forget_vehicles()
    {code, elem(StringIO.contents(out), 1) <> elem(StringIO.contents(err), 1)}
  end

  setup do
    Dolphin.Test.Instance.on_exit(&GroundStation.forget_vehicles/0)
  end

  test "every elixir block of docs/language.md says how it is checked" do
    blocks = blocks(File.read!(@doc_path))
    assert length(blocks) > 20
    unmarked = for {line, nil, _} <- blocks, do: line
    assert unmarked == [], "blocks without a <!-- run: ... --> or <!-- compile --> marker, at lines #{inspect(unmarked)}"
  end

  test "the compile-only examples compile" do
    for {line, :compile, code} <- blocks(File.read!(@doc_path)) do
      file = "docs/language.md:#{line}"

      case Dolphin.Script.compile_string(code, file) do
        {:ok, script} -> Dolphin.Script.purge(script)
        {:error, e} -> flunk("the example at #{file} does not compile: #{Dolphin.Script.Error.format(e)}")
      end
    end
  end

  test "the runnable examples run as documented", %{tmp_dir: dir} do
    runnable = for {line, %{} = m, code} <- blocks(File.read!(@doc_path)), do: {line, m, code}
    assert length(runnable) > 15

    for {line, m, code} <- runnable do
      path = Path.join(dir, "language_#{line}.exs")
      File.write!(path, code)
      {status, output} = run_script(path, m.args)
      where = "the example at docs/language.md:#{line} (mix dolphin.run #{Enum.join(m.args, " ")})"
      assert status == m.status, "#{where} exited with #{status}, not #{m.status}:\n#{output}"
      for text <- m.prints, do: assert(output =~ text, "#{where} did not print #{inspect(text)}:\n#{output}")
    end
  end
end
