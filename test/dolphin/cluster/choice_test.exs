defmodule Dolphin.Cluster.ChoiceTest do
  use ExUnit.Case, async: true

  alias Dolphin.Cluster.Choice
  alias Dolphin.Vehicles.View

  doctest Choice
  doctest Dolphin.Cluster.Error

  @view %View{id: 5, type: :uav, position: Dolphin.Geo.location(41.0, -8.0, 100)}

  defp h(age, loss, rtt, connected \\ true),
    do: %{view: %{@view | connected?: connected}, age_ms: age, link: %{rtt_ms: rtt, loss_in: loss, loss_out: loss}}

  test "a fresh chosen station is kept against a slightly better one, left for a clearly better one" do
    assert Choice.choose(%{a: h(10, 0.05, 40), b: h(10, 0.0, 35)}, :a) == :a
    assert Choice.choose(%{a: h(10, 0.3, 40), b: h(10, 0.0, 35)}, :a) == :b
    assert Choice.choose(%{a: h(10, 0.0, 100), b: h(10, 0.0, 20)}, :a) == :b
    # Unmeasured figures are no reason to leave a station.
    assert Choice.choose(%{a: h(10, nil, nil), b: h(10, 0.0, 20)}, :a) == :a
  end

  test "a stale or lost chosen station gives way to the best fresh one; with none fresh the choice stays" do
    assert Choice.choose(%{a: h(10_000, 0.0, 10), b: h(10, 0.2, 50), c: h(10, 0.0, 50)}, :a) == :c
    assert Choice.choose(%{a: h(10, 0.0, 10, false), b: h(10, 0.2, 50)}, :a) == :b
    assert Choice.choose(%{a: h(10_000, 0.0, 10), b: h(9_000, 0.0, 10)}, :a) == :a
    assert Choice.choose(%{b: h(9_000, 0.0, 10)}, :a) == :b
    assert Choice.choose(%{}, :a) == nil
    assert Choice.choose(%{a: h(10, 0.0, 10)}, nil) == :a
  end

  test "lost: no station has the vehicle connected" do
    assert Choice.lost?(%{})
    assert Choice.lost?(%{a: h(10, 0.0, 10, false)})
    refute Choice.lost?(%{a: h(10, 0.0, 10, false), b: h(90_000, 0.0, 10)})
  end

  test "two views of one id far apart are a conflict; close ones are one vehicle" do
    far = %{@view | position: Dolphin.Geo.location(41.01, -8.0, 100)}
    near = %{@view | position: Dolphin.Geo.location(41.0001, -8.0, 100)}
    assert {:conflict, why} = Choice.conflict(@view, far)
    assert why =~ "m apart"
    assert Choice.conflict(@view, near) == :same
  end

  test "a process working in an instance other than the default cannot join a station: only the default is part of a cluster" do
    Dolphin.Test.Instance.start!()
    assert {:error, %Dolphin.Cluster.Error{reason: :not_cluster_instance, detail: detail}} = Dolphin.Cluster.join(:"gs1@127.0.0.1")
    assert detail =~ ~r/cannot join gs1@127.0.0.1 from instance :dolphin_test_\d+: only the default instance \(Dolphin\) is part of a cluster/
  end
end
