defmodule Dolphin.Docs.ReadmeTest do
  # What the README shows a newcomer is what the code does: the event table
  # lists every event of the catalogue with its fields, the console's sample
  # is what the console prints, and the live view's endpoints are named.
  use ExUnit.Case, async: true

  @readme File.read!(Path.expand("../../README.md", __DIR__))

  # The rows of the `--events FILE` table: "| name, name | fields |".
  defp event_table do
    [_, section] = String.split(@readme, "### `--events FILE`", parts: 2)
    [section | _] = String.split(section, "\n### ", parts: 2)

    for "| " <> row <- String.split(section, "\n"),
        [names, fields] = row |> String.trim_trailing("|") |> String.split("|") |> Enum.map(&String.trim/1),
        names not in ["event", "---"],
        name <- String.split(names, ", "),
        into: %{},
        do: {name, fields}
  end

  test "the event table names every event of Dolphin.Telemetry, and no other" do
    table = event_table()
    catalogue = Dolphin.Telemetry.catalogue()
    names = catalogue |> Map.keys() |> Enum.map(&Atom.to_string/1)

    assert Enum.sort(names -- Map.keys(table)) == [], "events missing from the README's table"
    assert Enum.sort(Map.keys(table) -- names) == [], "the README's table names events that do not exist"

    for {name, fields} <- catalogue, field <- fields do
      assert table[Atom.to_string(name)] =~ Atom.to_string(field), "README: event #{name} does not list its field #{field}"
    end
  end

  test "the console sample's vehicles() table is what the console prints for those vehicles" do
    link = %{received: 100, lost: 0, rtt_ms: 0.0, loss_in: 0.0, loss_out: 0.0}
    base = %{type: "quadrotor", mode: "STABILIZE", armed: false, battery: 1.0, lat: 40.444233, alt: 0.0, link: link, lost?: false, activity: nil}

    printed =
      Dolphin.Console.Format.vehicles([
        Map.merge(base, %{id: 1, lon: -7.375411, seen_ms: 107}),
        Map.merge(base, %{id: 2, lon: -7.375057, seen_ms: 36})
      ])

    assert String.contains?(@readme, "iex(1)> vehicles()\n" <> printed <> "\n"), "README: the sample vehicles() table is not what the console prints:\n" <> printed
  end

  test "the live view's two endpoints are documented" do
    for endpoint <- ["`GET /`", "`GET /events`"], do: assert(String.contains?(@readme, endpoint), "README: #{endpoint} is not documented")
  end
end
