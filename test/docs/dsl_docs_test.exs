defmodule Dolphin.Docs.DSLDocsTest do
  # The language is documented where a user looks: `h battery` in the console,
  # `h Dolphin.Script`, and a doc with an example on every word a script uses.
  use ExUnit.Case, async: true

  import ExUnit.CaptureIO

  # The modules whose functions and macros are the words of scripts.
  @words [Dolphin.DSL, Dolphin.DSL.Values, Dolphin.DSL.Mission, Dolphin.DSL.Sensors, Dolphin.Mission.Command]

  defp docs(module) do
    {:docs_v1, _, :elixir, _, moduledoc, _, docs} = Code.fetch_docs(module)

    entries =
      for {{kind, name, arity}, _, _, doc, _} <- docs,
          kind in [:function, :macro],
          doc != :hidden,
          not String.starts_with?(Atom.to_string(name), "__"),
          do: {"#{inspect(module)}.#{name}/#{arity}", doc}

    {moduledoc, entries}
  end

  defp text(%{"en" => text}), do: text
  defp text(_none_or_hidden), do: ""

  test "every word of the language has a doc with an example (an indented code block or iex>)" do
    for module <- @words do
      {_, entries} = docs(module)
      assert entries != [], "#{inspect(module)} has no documented functions"
      missing = for {name, doc} <- entries, String.trim(text(doc)) == "", do: name
      assert missing == [], "no doc: #{Enum.join(missing, ", ")}"
      no_example = for {name, doc} <- entries, not (text(doc) =~ ~r/^    \S|^\s*iex>/m), do: name
      assert no_example == [], "no example in the doc: #{Enum.join(no_example, ", ")}"
    end
  end

  test "Dolphin.Script: an overview naming the reference, and a doc on every public function" do
    {moduledoc, entries} = docs(Dolphin.Script)
    overview = text(moduledoc)
    assert overview =~ "docs/language.md"
    for word <- ~w(pick battery mission until execute wait_for one_of all_of watch forever), do: assert(overview =~ "`#{word}")
    missing = for {name, doc} <- entries, String.trim(text(doc)) == "", do: name
    assert missing == [], "no doc: #{Enum.join(missing, ", ")}"
  end

  test "the reference the docs point at exists" do
    assert File.exists?(Path.expand("../../docs/language.md", __DIR__))
  end

  test "in the console, `h battery` and `h location` show the language's docs" do
    # The session's imports are what the project's .iex.exs makes of a fresh
    # IEx environment (IEx.Helpers imported, as IEx does).
    iex_exs = File.read!(Path.expand("../../.iex.exs", __DIR__))
    {env, _binding} = Code.eval_string("import IEx.Helpers\n" <> iex_exs <> "\n__ENV__", [], __ENV__)

    assert Macro.Env.lookup_import(env, {:battery, 1}) == [{:function, Dolphin.DSL}]
    assert Macro.Env.lookup_import(env, {:location, 3}) == [{:function, Dolphin.DSL.Values}]
    # The console's own helpers are still there, unambiguous.
    assert Macro.Env.lookup_import(env, {:vehicles, 0}) == [{:function, Dolphin.Console}]
    assert Macro.Env.lookup_import(env, {:watch, 2}) == [{:function, Dolphin.Console}]

    battery = capture_io(fn -> Code.eval_string("h battery", [], env) end)
    assert battery =~ "def battery(v)"
    assert battery =~ ~r/`nil`\s+until the vehicle has\s+reported it/
    assert battery =~ "until(survey, battery(v) < 0.3)"

    location = capture_io(fn -> Code.eval_string("h location", [], env) end)
    assert location =~ "metres above"
  end
end
