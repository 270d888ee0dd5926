defmodule Dolphin.Docs.LanguageBlocks do
  # The ```elixir blocks of docs/language.md and how each is checked. Each
  # block is preceded by a marker saying how:
  #
  #   <!-- run: --fake 2 | status 1 | prints "text" -->   run it, check its exit status (default 0)
  #                                                      and that its output holds each text
  #   <!-- compile -->                                    compile it only (long flights)
  #
  # A block without a marker is a mistake: examples that are never run rot.
  @moduledoc false

  @doc_path Path.expand("../../docs/language.md", __DIR__)

  def path, do: @doc_path

  # [{line, marker, code}] of every ```elixir block, in order.
  def blocks(text \\ File.read!(@doc_path)) do
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

  # The runnable blocks, [{line, marker, code}].
  def runnable, do: for({line, %{} = m, code} <- blocks(), do: {line, m, code})

  defp marker("<!-- compile -->"), do: :compile

  defp marker("<!-- run: " <> rest) do
    [args | checks] = rest |> String.trim_trailing(" -->") |> String.split(" | ")

    Enum.reduce(checks, %{args: OptionParser.split(args), status: 0, prints: []}, fn
      "status " <> n, m -> %{m | status: String.to_integer(n)}
      "prints " <> text, m -> %{m | prints: m.prints ++ [text |> String.trim("\"")]}
    end)
  end

  defp marker(_), do: nil
end

defmodule Dolphin.Docs.LanguageTest do
  # Every example of docs/language.md is checked (Dolphin.Docs.LanguageBlocks):
  # here, that each says how and that the compile-only ones compile; the
  # runnable ones run, as a user runs them (`mix dolphin.run FILE ARGS` on
  # fake vehicles or the simulator), in the modules below.
  use ExUnit.Case, async: true

  alias Dolphin.Docs.LanguageBlocks

  @external_resource LanguageBlocks.path()

  test "every elixir block of docs/language.md says how it is checked" do
    blocks = LanguageBlocks.blocks()
    assert length(blocks) > 20
    unmarked = for {line, nil, _} <- blocks, do: line
    assert unmarked == [], "blocks without a <!-- run: ... --> or <!-- compile --> marker, at lines #{inspect(unmarked)}"
  end

  test "the compile-only examples compile" do
    for {line, :compile, code} <- LanguageBlocks.blocks() do
      file = "docs/language.md:#{line}"

      case Dolphin.Script.compile_string(code, file) do
        {:ok, script} -> Dolphin.Script.purge(script)
        {:error, e} -> flunk("the example at #{file} does not compile: #{Dolphin.Script.Error.format(e)}")
      end
    end
  end

  test "there are runnable examples, each run by one of the modules below" do
    assert length(LanguageBlocks.runnable()) > 15
  end
end

# The runnable examples, a share of them per module: the modules run side by
# side, each in its own Dolphin.Instance (its vehicles, links and clock).
for share <- 0..3 do
  defmodule Module.concat(Dolphin.Docs.LanguageTest, "Runs#{share}") do
    use ExUnit.Case, async: true

    alias Dolphin.Docs.LanguageBlocks
    alias Dolphin.Test.GroundStation
    alias Mix.Tasks.Dolphin.Run

    @moduletag :tmp_dir
    # Some 50 s a share on a quiet machine; each script's pre-flight dry run
    # waits its turn (one at a time in a VM, Dolphin.Check), and with both
    # cores busy elsewhere a share passed 300 s.
    @moduletag timeout: 900_000
    @external_resource LanguageBlocks.path()
    @share share

    setup do
      Dolphin.Test.Instance.start!()
      Dolphin.Test.Instance.on_exit(&GroundStation.forget_vehicles/0)
    end

    defp run_script(path, args) do
      {:ok, out} = StringIO.open("")
      {:ok, err} = StringIO.open("")
      code = Run.main([path | args] ++ ["--no-tlog"], out: out, err: err)
      GroundStation.forget_vehicles()
      {code, elem(StringIO.contents(out), 1) <> elem(StringIO.contents(err), 1)}
    end

    test "the runnable examples run as documented (share #{share} of 4)", %{tmp_dir: dir} do
      mine = LanguageBlocks.runnable() |> Enum.with_index() |> Enum.filter(fn {_, i} -> rem(i, 4) == @share end)
      assert mine != []

      for {{line, m, code}, _} <- mine do
        path = Path.join(dir, "language_#{line}.exs")
        File.write!(path, code)
        {status, output} = run_script(path, m.args)
        where = "the example at docs/language.md:#{line} (mix dolphin.run #{Enum.join(m.args, " ")})"
        assert status == m.status, "#{where} exited with #{status}, not #{m.status}:\n#{output}"
        for text <- m.prints, do: assert(output =~ text, "#{where} did not print #{inspect(text)}:\n#{output}")
      end
    end
  end
end
