defmodule Dolphin.SITL.Pace do
  @moduledoc false
  # Keeps the ground station's clock at the pace SITL vehicles really fly
  # (see Dolphin.SITL, "Pace"). Each ArduPilot runs its own clock at the
  # --speedup it was given while the machine has the cores for it; on a
  # loaded machine it falls behind (measured: 0.43 to 0.81 of 15x with other
  # test runs beside it). The script's time (every `during`, the run's
  # `--for`, the charging) is the clock's, so a clock running ahead of the
  # vehicles asks of them more than their time allows: a survey cut short
  # before its battery ran down. Once a second (real time), this compares
  # each vehicle's time_boot_ms with the moment it arrived, over the last
  # few seconds, and sets the clock's speed-up to the slowest vehicle's
  # pace, never above the speed-up asked for. Stopped (the fleet stops), it
  # gives the clock back the speed-up asked for.

  use GenServer, restart: :temporary

  alias Dolphin.{Clock, Vehicles}

  @every_real_ms 1_000
  # The pace is measured over at least this much real time (one second of
  # a vehicle's 10 Hz positions holds its scheduling jitter).
  @window_real_us 3_000_000
  # Changes smaller than this share of the speed-up are left alone.
  @deadband 0.03
  # Never slower than this share of the speed-up asked for: a vehicle that
  # stopped (SIGSTOP, a debugger) is lost, not followed.
  @least_share 0.1

  def start_link(opts), do: GenServer.start_link(__MODULE__, Map.new(opts))

  @impl true
  def init(%{ids: ids, speedup: k}) do
    # So that a supervisor's shutdown runs terminate/2.
    Process.flag(:trap_exit, true)
    Process.send_after(self(), :measure, @every_real_ms)
    {:ok, %{ids: ids, asked: k, samples: %{}}}
  end

  @impl true
  def handle_info(:measure, s) do
    Process.send_after(self(), :measure, @every_real_ms)
    samples = Map.new(s.ids, fn id -> {id, sample(id, Map.get(s.samples, id, []))} end)
    paces = for {_id, kept} <- samples, pace = pace(kept), do: pace

    if paces != [] do
      target = paces |> Enum.min() |> min(s.asked) |> max(s.asked * @least_share)
      current = Clock.speedup()
      # Back at full pace, exactly the speed-up asked for, however near the
      # clock came on its way up (a loaded host measured 9.94 of 10, then
      # stayed there, within the deadband).
      cond do
        target == s.asked and current != s.asked -> Clock.set_speedup(s.asked)
        abs(target - current) > @deadband * s.asked -> Clock.set_speedup(Float.round(target * 1.0, 2))
        true -> :ok
      end
    end

    {:noreply, %{s | samples: samples}}
  end

  @impl true
  def terminate(_reason, s), do: Clock.set_speedup(s.asked)

  # The vehicle's {time_boot_ms, µs} samples of the last window, newest
  # first; a reboot (its clock going back) starts them again.
  defp sample(id, kept) do
    case Vehicles.state(id) do
      {:ok, %{boot: {t, us} = new}} ->
        kept = if match?([{t0, _} | _] when t0 > t, kept), do: [], else: kept
        [new | Enum.take_while(kept, fn {_, u} -> us - u <= @window_real_us end)] |> Enum.dedup()

      _ ->
        kept
    end
  end

  # Vehicle ms per real ms over the samples, once they span a second.
  defp pace([{t1, us1} | _] = kept) do
    {t0, us0} = List.last(kept)
    if us1 - us0 >= 1_000_000, do: (t1 - t0) / ((us1 - us0) / 1000)
  end

  defp pace([]), do: nil
end
