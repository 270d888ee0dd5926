defmodule Dolphin.SITL.Charger do
  @moduledoc false
  # The SITL fleet's charging station (see Dolphin.SITL, "Charging"): SITL's
  # battery only ever drains, so a landed, disarmed vehicle has its remaining
  # charge raised at the simulator's rate with MAV_CMD_BATTERY_RESET, which
  # ArduPilot's battery monitor takes as the new remaining percentage.

  use GenServer, restart: :temporary

  alias Dolphin.Vehicles

  # Clock time between two top-ups: a whole percent at 0.5 %/s, so that every
  # reset moves the reported (integer) percentage.
  @period_ms 2_000

  def start_link(opts), do: GenServer.start_link(__MODULE__, Map.new(opts))

  @impl true
  def init(%{sysids: sysids, per_s: per_s}) do
    Dolphin.Clock.send_after(self(), :charge, @period_ms)
    {:ok, %{sysids: sysids, per_s: per_s, charge: %{}, last_ms: Dolphin.Clock.now_ms()}}
  end

  @impl true
  def handle_info(:charge, s) do
    now = Dolphin.Clock.now_ms()
    gained = s.per_s * (now - s.last_ms) / 1000
    charge = Map.new(s.sysids, fn id -> {id, top_up(id, Map.get(s.charge, id), gained)} end)
    Dolphin.Clock.send_after(self(), :charge, @period_ms)
    {:noreply, %{s | charge: charge, last_ms: now}}
  end

  # The charge is kept here as a float (the autopilot reports whole percents);
  # nil while the vehicle is not charging.
  defp top_up(id, charging, gained) do
    case Vehicles.view(id) do
      {:ok, %{armed?: false, landed: landed, battery: battery}} when landed in [:on_ground, nil] and is_number(battery) and battery < 1.0 ->
        level = min(100.0, max(charging || battery * 100, battery * 100) + gained)
        # A command that is not answered (a busy link) is tried again at the next top-up.
        _ = Vehicles.command(id, :mav_cmd_battery_reset, [1, Float.round(level, 1)], attempts: 1)
        level

      _ ->
        nil
    end
  end
end
