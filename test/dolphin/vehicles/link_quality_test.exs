defmodule Dolphin.Vehicles.LinkQualityTest do
  # The link's figures as a pure state machine, then measured on simulated vehicles
  # over a clean link and behind the impairment proxy. Its own Dolphin.Instance (its
  # vehicles, links and clock): async.
  use ExUnit.Case, async: true

  setup do
    Dolphin.Test.Instance.start!()
    :ok
  end

  alias Dolphin.{Sim, Vehicles}
  alias Dolphin.Vehicles.{LinkQuality, State}
  alias Dolphin.Test.{GroundStation, UDPProxy, Wait}

  doctest LinkQuality

  describe "the figures" do
    test "nil until measured; the round trip is the median of the latest answers" do
      q = LinkQuality.new()
      assert LinkQuality.figures(q) == %{rtt_ms: nil, loss_in: nil, loss_out: nil, loss_rt: nil}

      q = Enum.reduce([{1, 10}, {2, 500}, {3, 12}], q, fn {ts, rtt}, q -> q |> LinkQuality.request(ts, 0) |> LinkQuality.reply(ts, rtt) end)
      assert LinkQuality.figures(q).rtt_ms == 12
      # An answer to nothing of ours (another ground station's, a repeat) changes nothing.
      assert LinkQuality.reply(q, 99, 5) == q
      assert LinkQuality.reply(q, 1, 5) == q
    end

    test "TIMESYNCs unanswered in time are the round-trip loss; loss out follows from it and the sequence gaps" do
      q =
        Enum.reduce(1..10, LinkQuality.new(), fn ts, q ->
          q = LinkQuality.request(q, ts, ts * 1_000)
          if rem(ts, 2) == 0, do: LinkQuality.reply(q, ts, ts * 1_000 + 30), else: q
        end)

      # Half the frames from the vehicle lost on the way.
      q = q |> LinkQuality.frames(50, 50) |> LinkQuality.measure(20_000, 2_000)
      f = LinkQuality.figures(q)
      assert f.loss_rt == 0.5
      assert f.loss_in == 0.5
      # 1 - (1 - 0.5) / (1 - 0.5): what came back lost nothing on the way out.
      assert f.loss_out == 0.0

      # Too few frames: no new loss_in sample; a late answer is still no answer.
      q = q |> LinkQuality.frames(3, 0) |> LinkQuality.measure(21_000, 2_000)
      assert LinkQuality.figures(q).loss_in == 0.5
    end
  end

  describe "on simulated vehicles" do
    setup do
      %{gcs_port: GroundStation.open()}
    end

    defp flush_views do
      receive do
        {:dolphin, {:vehicle, _}, {:view, view}} -> [view | flush_views()]
      after
        0 -> []
      end
    end

    defp figures(id), do: with({:ok, state} <- Vehicles.state(id), do: State.link_figures(state))

    test "a clean link: a round trip, no loss", %{gcs_port: port} do
      {:ok, [1]} = Sim.start(count: 1, gcs: port)
      Wait.until(fn -> match?(%{rtt_ms: r, loss_out: o} when is_number(r) and is_number(o), figures(1)) end, 10_000, fn -> "figures: #{inspect(figures(1))}" end)
      f = figures(1)
      assert f.loss_in == 0.0 and f.loss_out == 0.0 and f.loss_rt == 0.0
    end

    test "behind a link that loses 30 % each way, both losses show", %{gcs_port: port} do
      proxy = start_supervised!({UDPProxy, gcs: port, seed: 5, both: [loss: 0.3]})
      {:ok, [1]} = Sim.start(count: 1, gcs: UDPProxy.port(proxy))
      Vehicles.subscribe(1)

      # Once 20 TIMESYNCs have had their chance, the figures are the link's.
      outcomes = fn -> with {:ok, st} <- Vehicles.state(1), do: length(st.link_quality.outcomes) end
      Wait.until(fn -> outcomes.() == 20 end, 40_000, fn -> "TIMESYNCs judged: #{inspect(outcomes.())}" end)
      # Twenty samples of a 30 % loss (51 % for a round trip): within three
      # standard deviations (a loaded run of the suite, fleets flying beside
      # it, saw 4 round trips of 20 lost).
      f = figures(1)
      assert f.loss_in > 0.1 and f.loss_in < 0.5, inspect(f)
      assert f.loss_rt > 0.15 and f.loss_rt < 0.85, inspect(f)
      assert is_number(f.rtt_ms)
      # Subscribers are told the figures.
      assert Enum.any?(flush_views(), &match?(%{link: %{loss_in: i}} when is_number(i), &1))
    end
  end
end
