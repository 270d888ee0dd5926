defmodule Dolphin.Docs.ReadmeTest do
  # What the README and docs/ show a newcomer is what the code does: the
  # event table lists every event of the catalogue with its fields, the
  # console's sample is what the console prints, the live view's endpoints
  # are named, the first script is the example the scenario tests fly, and
  # every link between the documents leads somewhere.
  use ExUnit.Case, async: true

  @root Path.expand("../..", __DIR__)
  @readme File.read!(Path.join(@root, "README.md"))
  @operating File.read!(Path.join(@root, "docs/operating.md"))

  # The rows of the `--events FILE` table: "| name, name | fields |".
  defp event_table do
    [_, section] = String.split(@operating, "### `--events FILE`", parts: 2)
    [section | _] = String.split(section, "\n### ", parts: 2)

    for "| " <> row <- String.split(section, "\n"),
        [names, fields] = row |> String.trim_trailing("|") |> String.split("|") |> Enum.map(&String.trim/1),
        names not in ["event", "---"],
        name <- String.split(names, ", "),
        into: %{},
        do: {name, fields}
  end

  test "docs/operating.md: the event table names every event of Dolphin.Events, and no other" do
    table = event_table()
    catalogue = Dolphin.Events.catalogue()
    names = catalogue |> Map.keys() |> Enum.map(&Atom.to_string/1)

    assert Enum.sort(names -- Map.keys(table)) == [], "events missing from the table"
    assert Enum.sort(Map.keys(table) -- names) == [], "the table names events that do not exist"

    for {name, fields} <- catalogue, field <- fields do
      assert table[Atom.to_string(name)] =~ Atom.to_string(field), "docs/operating.md: event #{name} does not list its field #{field}"
    end
  end

  test "the console sample's vehicles() table is what the console prints for those vehicles" do
    link = %{received: 100, lost: 0, rtt_ms: 0.0, loss_in: 0.0, loss_out: 0.0}
    base = %{type: "uav", airframe: "copter", mode: "STABILIZE", armed: false, battery: 1.0, lat: 40.444233, alt: 0.0, link: link, lost?: false, activity: nil}

    printed =
      Dolphin.Console.Format.vehicles([
        Map.merge(base, %{id: 1, lon: -7.375411, seen_ms: 107}),
        Map.merge(base, %{id: 2, lon: -7.375057, seen_ms: 36})
      ])

    assert String.contains?(@operating, "iex(1)> vehicles()\n" <> printed <> "\n"), "docs/operating.md: the sample vehicles() table is not what the console prints:\n" <> printed
  end

  test "the live view's two endpoints are documented" do
    for endpoint <- ["`GET /`", "`GET /events`"], do: assert(String.contains?(@operating, endpoint), "docs/operating.md: #{endpoint} is not documented")
  end

  test "the README's first script is examples/single_vehicle.exs, which the scenario tests fly" do
    example = File.read!(Path.join(@root, "examples/single_vehicle.exs"))
    [_comments, body] = String.split(example, "use Dolphin.Script", parts: 2)
    assert String.contains?(@readme, "```elixir\nuse Dolphin.Script" <> String.trim_trailing(body) <> "\n```"), "README: the first script differs from examples/single_vehicle.exs"
  end

  test "every relative link of the README and docs/ leads to a file that exists" do
    files = [Path.join(@root, "README.md") | Path.wildcard(Path.join(@root, "docs/*.md"))]

    broken =
      for file <- files,
          [_, target] <- Regex.scan(~r/\]\(([^)#\s]+)(?:#[^)]*)?\)/, File.read!(file)),
          not String.contains?(target, "://"),
          not File.exists?(Path.expand(target, Path.dirname(file))),
          do: "#{Path.relative_to(file, @root)}: #{target}"

    assert broken == [], "broken links: #{Enum.join(broken, ", ")}"
  end

  test "docs/architecture.md's supervision tree names every child of Dolphin.Supervisor and of the default instance, in order" do
    doc = File.read!(Path.join(@root, "docs/architecture.md"))
    [_, tree] = String.split(doc, "Dolphin.Supervisor (rest_for_one", parts: 2)
    [tree | _] = String.split(tree, "```", parts: 2)
    lines = String.split(tree, "\n")
    drawn = for line <- lines, [_, name] <- [Regex.run(~r/^[├└]─ (\S+(?: links)?)/u, line)], do: name
    # The default instance's children: the lines drawn under it, up to the next child of the root.
    under_instance = lines |> Enum.drop_while(&(not String.starts_with?(&1, "├─ Dolphin.Instance"))) |> tl() |> Enum.take_while(&String.starts_with?(&1, "│"))
    drawn_in_instance = for line <- under_instance, [_, name] <- [Regex.run(~r/^│    [├└]─ (\S+(?: links)?)/u, line)], do: name

    named = fn supervisor ->
      for {id, _pid, _type, _modules} <- Enum.reverse(Supervisor.which_children(supervisor)) do
        case id do
          :cluster_scope -> "Dolphin.Cluster.Scope"
          :configured_links -> "configured links"
          {Dolphin.Instance, Dolphin} -> "Dolphin.Instance"
          module -> inspect(module)
        end
      end
    end

    assert drawn == named.(Dolphin.Supervisor)
    [instance] = for {{Dolphin.Instance, Dolphin}, pid, :supervisor, _} <- Supervisor.which_children(Dolphin.Supervisor), do: pid
    assert drawn_in_instance == named.(instance)
  end
end
