defmodule Dolphin.Sim.Copter.Modes do
  @moduledoc false
  # The simulated copter's flight modes and arming, as ArduCopter rules them:
  # which modes need a position estimate or a mission, which cannot be armed
  # in, what entering and leaving a mode does to the navigation target, the
  # disarm on the ground (land detector, DISARM_DELAY), and the GCS failsafe's
  # switch to RTL. Answers are MAV_RESULT codes, as the command protocol acks.

  import Dolphin.Sim.Copter, only: [text: 3, in_air?: 1, ready?: 1, flies?: 1, mav_type: 1, home_ne: 1, surface: 1]

  alias Dolphin.Sim.{Copter, MissionServer}
  alias Dolphin.Sim.Copter.Mission
  alias Dolphin.Vehicles.Modes, as: Names

  # MAV_RESULT
  @accepted 0
  @failed 4

  # Mode behaviour groups.
  @pilot_modes [:stabilize, :acro, :alt_hold, :loiter, :drift, :sport, :flip, :autotune, :poshold, :throw,
                :guided_nogps, :flowhold, :zigzag, :systemid, :autorotate, :turtle, :circle, :follow, :avoid_adsb,
                :smart_rtl, :auto_rtl]
  # GUIDED is entered before the position estimate is ready (ARDUPILOT.md:
  # arming in GUIDED is what is refused until then).
  @not_armable [:auto, :rtl, :land, :brake, :circle, :smart_rtl, :auto_rtl, :follow, :avoid_adsb, :throw, :autorotate]
  @needs_position [:auto, :loiter, :rtl, :circle, :poshold, :brake, :follow, :smart_rtl, :zigzag, :auto_rtl]

  @type result :: 0 | 4

  # ---------------------------------------------------------------------------
  # Arming.

  @spec arm(Copter.t(), boolean()) :: {result(), Copter.t()}
  def arm(%{armed: true} = c, _force), do: {@accepted, c}

  def arm(c, force?) do
    reason =
      cond do
        force? -> nil
        # ArduRover arms in AUTO (it waits there); ArduSub arms in any mode, without a position.
        c.config.airframe == :copter and c.mode in @not_armable -> "Arm: #{c.mode |> Atom.to_string() |> String.upcase()} mode not armable"
        c.config.airframe == :sub -> nil
        not ready?(c) -> "Arm: Need Position Estimate"
        c.home == nil -> "Arm: Need Position Estimate"
        c.battery < c.config.arm_min_battery or c.arm_blocked -> "Arm: Battery 1 below minimum arming capacity"
        true -> nil
      end

    if reason do
      {@failed, text(c, 2, reason)}
    else
      # ArduCopter writes home into the mission's item 0 as it arms.
      c = %{c | armed: true, ground_since: c.time_ms, failsafe: nil, jumps: %{}, missions: MissionServer.home_written(c.missions)}
      {@accepted, c |> text(6, "Arming motors") |> disarm_at_arming()}
    end
  end

  # The :disarms_at_arming fault: armed and disarmed in one instant (no
  # HEARTBEAT says it was armed), as ArduRover SITL once did on a loaded host.
  defp disarm_at_arming(%{config: %{disarms_at_arming: n} = config} = c) when n > 0,
    do: disarm_now(%{c | config: %{config | disarms_at_arming: n - 1}})

  defp disarm_at_arming(c), do: c

  @spec disarm(Copter.t(), boolean()) :: {result(), Copter.t()}
  def disarm(%{armed: false} = c, _force), do: {@accepted, c}

  def disarm(c, force?) do
    if in_air?(c) and not force? do
      {@failed, text(c, 2, "Disarm: vehicle is flying")}
    else
      {@accepted, disarm_now(c)}
    end
  end

  @spec disarm_now(Copter.t()) :: Copter.t()
  def disarm_now(c) do
    c = %{c | armed: false, ground_since: nil, nav: :idle, capture: nil}
    c = if in_air?(c), do: c, else: %{c | landed: :on_ground, vz: 0.0}
    c = text(c, 6, "Disarming motors")
    # A landed copter's mission starts again from item 1.
    Mission.finish_landing_item(%{c | resume: nil})
  end

  # DISARM_DELAY: armed on the ground with nothing to do (a copter's); 0
  # turns it off, as on ArduCopter.
  @spec auto_disarm(Copter.t()) :: Copter.t()
  def auto_disarm(%{armed: true, landed: :on_ground, nav: :idle, ground_since: since, config: %{airframe: :copter, disarm_delay_ms: delay}} = c) when since != nil and delay > 0 do
    if c.time_ms - since >= c.config.disarm_delay_ms, do: disarm_now(c), else: c
  end

  def auto_disarm(c), do: c

  # ---------------------------------------------------------------------------
  # Modes.

  # A mode by its ArduCopter number.
  @spec set_mode(Copter.t(), integer()) :: {result(), Copter.t()}
  def set_mode(c, number) do
    case Names.name(:ardupilot, mav_type(c), number) do
      {:custom, _} -> {@failed, c}
      name -> set_mode_named(c, name)
    end
  end

  @spec set_mode_named(Copter.t(), atom()) :: {result(), Copter.t()}
  def set_mode_named(%{mode: mode} = c, mode), do: {@accepted, c}

  def set_mode_named(c, mode) do
    cond do
      (mode in @needs_position or (c.config.airframe == :sub and mode == :guided)) and not ready?(c) ->
        {@failed, text(c, 2, "Mode change to #{upcase(mode)} failed: requires position")}

      mode == :auto and MissionServer.items(c.missions) == [] ->
        {@failed, text(c, 2, "Mode change to AUTO failed: no mission")}

      mode == :auto and flies?(c) and c.armed and not in_air?(c) and not Mission.starts_with_takeoff?(c) ->
        {@failed, text(c, 2, "Auto: Missing Takeoff Cmd")}

      true ->
        {@accepted, c |> abandon_takeoff(mode) |> leave_mode() |> enter_mode(mode)}
    end
  end

  # A copter whose motors still spool up for a take-off, put in any mode but
  # AUTO, never leaves the ground: it stands armed there, and DISARM_DELAY
  # counts from now (ArduCopter SITL, put in BRAKE during the spool-up,
  # disarmed itself 10-12 s later).
  defp abandon_takeoff(%{config: %{airframe: :copter}, armed: true, landed: :takeoff} = c, mode) when mode != :auto,
    do: if(in_air?(c), do: c, else: %{c | landed: :on_ground, ground_since: c.time_ms})

  defp abandon_takeoff(c, _mode), do: c

  defp upcase(mode), do: mode |> Atom.to_string() |> String.upcase()

  defp leave_mode(%{mode: :auto} = c) do
    # Leaving AUTO keeps the interrupted item to resume from.
    c = %{c | resume: if(c.mission_state == 3 and c.current > 0, do: c.current, else: c.resume), item: nil}
    c = if c.mission_state == 3, do: %{c | mission_state: 2}, else: c
    Mission.mission_current(c)
  end

  defp leave_mode(c), do: c

  # A rover, boat or submarine: RTL drives home, SURFACE rises where it is
  # (then ALT_HOLD), every other mode stops it where it is and holds (a
  # rover's HOLD only cuts the throttle: it coasts to a stop).
  # A plane circles wherever it holds: LOITER, GUIDED and the rest where it
  # is, RTL over home; on the ground nothing moves.
  defp enter_mode(%{config: %{airframe: :plane}} = c, mode) when mode != :auto do
    nav =
      cond do
        not in_air?(c) -> :idle
        mode == :rtl -> {:rtl, :climb}
        true -> {:hold, c.n, c.e, c.alt}
      end

    %{c | mode: mode, nav: nav}
  end

  defp enter_mode(%{config: %{airframe: airframe}} = c, mode) when airframe in [:rover, :boat, :sub] and mode != :auto do
    nav =
      cond do
        not c.armed -> :idle
        mode in [:rtl, :smart_rtl] and airframe != :sub -> with({hn, he} <- home_ne(c), do: {:goto, hn, he, c.alt})
        mode == :surface -> {:goto, c.n, c.e, surface(c)}
        true -> {:brake}
      end

    %{c | mode: mode, nav: nav}
  end

  defp enter_mode(c, :auto) do
    c = %{c | mode: :auto}
    first = c.resume || 1
    Mission.start_item(%{c | resume: nil}, first)
  end

  defp enter_mode(c, :guided), do: %{c | mode: :guided, nav: if(in_air?(c), do: {:brake}, else: :idle)}
  defp enter_mode(c, :brake), do: %{c | mode: :brake, nav: if(in_air?(c), do: {:brake}, else: :idle)}

  defp enter_mode(c, :rtl) do
    c = %{c | mode: :rtl}
    if in_air?(c), do: %{c | nav: {:rtl, :climb}}, else: ground_landing_mode(c)
  end

  defp enter_mode(c, :land) do
    c = %{c | mode: :land}
    if in_air?(c), do: %{c | nav: {:land, c.n, c.e}, landed: :landing}, else: ground_landing_mode(c)
  end

  defp enter_mode(c, mode) when mode in @pilot_modes do
    # No RC throttle: a pilot-controlled mode sinks (ARDUPILOT.md: never a hold).
    c = %{c | mode: mode}
    if in_air?(c), do: %{c | nav: {:descend}}, else: %{c | nav: :idle}
  end

  defp enter_mode(c, mode), do: %{c | mode: mode, nav: if(in_air?(c), do: {:descend}, else: :idle)}

  # RTL or LAND on the ground: the land detector disarms at once.
  defp ground_landing_mode(%{armed: true} = c), do: disarm_now(%{c | nav: :idle})
  defp ground_landing_mode(c), do: %{c | nav: :idle}

  # FS_GCS_ENABLE: in the air and nothing heard from the ground station for 5 s.
  @spec gcs_failsafe(Copter.t()) :: Copter.t()
  def gcs_failsafe(%{config: %{gcs_failsafe: true, airframe: :copter}, gcs_heard_ms: heard, failsafe: nil} = c) when heard != nil do
    if in_air?(c) and c.time_ms - heard > 5_000 do
      c = %{text(c, 2, "GCS Failsafe") | failsafe: :gcs}
      {_, c} = set_mode_named(c, :rtl)
      c
    else
      c
    end
  end

  def gcs_failsafe(c), do: c
end
