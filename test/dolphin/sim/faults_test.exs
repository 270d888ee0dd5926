defmodule Dolphin.Sim.FaultsTest do
  use ExUnit.Case, async: true

  alias Dolphin.Sim.Faults

  doctest Faults

  defp deliver(faults, n) do
    Enum.map_reduce(1..n, faults, fn i, f -> Faults.apply(f, <<i::32, "payload">>) end)
  end

  test "no faults: every datagram, at once" do
    {deliveries, _} = deliver(Faults.new(%{}, 1), 100)
    assert Enum.all?(deliveries, &match?([{0, _}], &1))
  end

  test "the same seed draws the same faults; rates are about what was asked" do
    faults = %{loss: 0.2, duplicate: 0.1, reorder: 0.1, corrupt: 0.05, latency: 30}
    {a, _} = deliver(Faults.new(faults, :seed), 5_000)
    {b, _} = deliver(Faults.new(faults, :seed), 5_000)
    assert a == b

    lost = Enum.count(a, &(&1 == []))
    twice = Enum.count(a, &(length(&1) == 2))
    late = Enum.count(a, fn d -> Enum.any?(d, fn {delay, _} -> delay > 30 end) end)
    assert lost in 850..1150
    assert twice in 300..500
    assert late in 300..500
    assert Enum.all?(List.flatten(a), fn {delay, _} -> delay >= 30 and delay <= 130 end)

    corrupted = a |> Enum.with_index(1) |> Enum.count(fn {d, i} -> Enum.any?(d, fn {_, bytes} -> bytes != <<i::32, "payload">> end) end)
    assert corrupted in 120..280
  end

  test "silence lets nothing through; bad faults are refused with what is allowed" do
    {deliveries, _} = deliver(Faults.new(%{silence: true}, 1), 10)
    assert Enum.all?(deliveries, &(&1 == []))
    assert_raise ArgumentError, ~r/bad fault :loss: 2/, fn -> Faults.new(%{loss: 2}, 1) end
    assert_raise ArgumentError, ~r/bad fault :jitter/, fn -> Faults.new(%{jitter: 1}, 1) end
  end
end
