defmodule Dolphin.Mission.Executor.Flight do
  @moduledoc false
  # The executor's judgement of a mission in flight, pure: from the vehicle's
  # views (Dolphin.Vehicles.View), each in turn, to progress and an end (done, or the
  # vehicle left the mission), with what it has seen of this flight.

  defstruct [:ending, active: false, armed_seen: false, auto_seen: false, airborne_seen: false, landing_check: false, on_land_item: false, progress: nil]

  @typedoc "How the mission ends (`Dolphin.Mission.ending/1`) and what this flight has shown so far."
  @type t :: %__MODULE__{
          ending: {:landing, non_neg_integer()} | {:reached, non_neg_integer()} | term(),
          active: boolean(),
          armed_seen: boolean(),
          auto_seen: boolean(),
          airborne_seen: boolean(),
          landing_check: boolean(),
          on_land_item: boolean(),
          progress: map() | nil
        }

  @typedoc """
  `:flying`; `:done`; `{:left, cause}`: the vehicle left the mission (a failsafe,
  the pilot), to be left to what took it; `:check_landed`: a landing mission's
  vehicle disarmed, whose last reports are still to come.
  """
  @type verdict :: :flying | :done | {:left, Dolphin.Mission.Failure.cause()} | :check_landed

  @spec new(term()) :: t()
  def new(ending), do: %__MODULE__{ending: ending}

  @doc false
  # MISSION_CURRENT's ACTIVE may come before the heartbeat shows AUTO and be
  # gone by the next view (a mission that completes at once): a view that
  # shows this mission ACTIVE counts, whatever its mode (the mission state is
  # reset by the upload, so an ACTIVE after it is this mission's).
  @spec reported(t(), Dolphin.Vehicles.View.t()) :: t()
  def reported(f, %{mission: %{state: :active}}), do: %{f | active: true}
  def reported(f, _view), do: f

  @doc false
  # The verdict on a state of the vehicle, and the progress to report (nil:
  # none new).
  @spec judge(t(), Dolphin.Vehicles.View.t()) :: {verdict(), map() | nil, t()}
  def judge(f, st) do
    mission = st.mission
    f = observe(f, st)
    active = f.active
    # After its final landing ArduCopter resets the mission to item 1, often
    # before the heartbeat shows the disarm: that is no progress of this mission.
    {progress, f} = if f.on_land_item and not on_land_item?(f, mission), do: {nil, f}, else: progress(f, mission)

    cond do
      not active ->
        {:flying, progress, f}

      complete?(f, st) ->
        {:done, progress, f}

      f.auto_seen and st.mode != :auto ->
        {{:left, {:left_auto, mode_name(st.mode)}}, progress, f}

      f.armed_seen and not st.armed? and not match?({:landing, _}, f.ending) ->
        {{:left, :disarmed}, progress, f}

      f.armed_seen and not st.armed? and not f.landing_check ->
        {:check_landed, progress, %{f | landing_check: true}}

      true ->
        {:flying, progress, f}
    end
  end

  @doc false
  # What a state of the vehicle shows of the flight, judged or not: a short
  # mission may be flown, even landed, while MISSION_START's answer is still
  # on its way, and what was seen then counts.
  @spec observe(t(), Dolphin.Vehicles.View.t()) :: t()
  def observe(f, st) do
    mission = st.mission
    # The mission counts as running once the vehicle reports it active in AUTO,
    # or reports an item of it reached (progress restarts at every upload): a
    # mission that ends in the loop that starts it is only ever reported
    # COMPLETE, as ArduCopter sends the latest MISSION_CURRENT only. Before
    # that, the state still describes the previous mission.
    active = f.active or (st.mode == :auto and mission.state == :active) or mission.reached != nil
    # Reports travel separately (mode and armed bit with the 1 Hz heartbeat,
    # the mission state with MISSION_CURRENT): leaving AUTO or disarming counts
    # only once the heartbeat has shown AUTO, or armed, during this mission.
    f = %{f | active: active, armed_seen: f.armed_seen or (active and st.armed?), auto_seen: f.auto_seen or (active and st.mode == :auto), airborne_seen: f.airborne_seen or (active and airborne?(st))}
    %{f | on_land_item: f.on_land_item or (active and st.armed? and on_land_item?(f, mission))}
  end

  @doc false
  # A landing mission's vehicle disarmed some time ago: its reports have come.
  @spec landed(t(), Dolphin.Vehicles.View.t()) :: :done | {:failed, Dolphin.Mission.Failure.cause()}
  def landed(f, st) do
    if complete?(f, st),
      do: :done,
      else: {:failed, {:landed_early, st.mission.current, st.mission.total}}
  end

  # ArduPilot reports the end with MISSION_CURRENT state COMPLETE (after the
  # landing and disarm when the mission lands); `reached` of the last item
  # counts too, for autopilots without mission states.
  # ArduCopter reports a final RETURN_TO_LAUNCH reached after the disarm, but
  # a final NAV_LAND never: it disarms with the land item still current and
  # the mission ACTIVE (docs/ardupilot.md), so landed and disarmed at the last
  # item is the end.
  defp complete?(%{ending: {:landing, seq}} = f, st),
    do: f.armed_seen and not st.armed? and (st.mission.state == :complete or st.mission.reached == seq or landed_at_end?(f, st))

  defp complete?(%{ending: {:reached, seq}}, st), do: st.mission.state == :complete or (st.mission.state == nil and st.mission.reached == seq)
  defp complete?(_forever, _st), do: false

  # After that disarm ArduCopter resets its mission to item 1, often reported
  # before the heartbeat shows the disarm: what counts is that the vehicle
  # flew the final land item armed, then disarmed on the ground.
  defp landed_at_end?(f, st), do: f.on_land_item and st.landed in [:on_ground, nil]

  # Off the ground: said so, or a metre above home while taking off or with
  # no landed state reported.
  defp airborne?(%{landed: landed}) when landed in [:in_air, :landing], do: true
  defp airborne?(%{landed: landed, relative_altitude: h}) when landed in [nil, :takeoff] and is_number(h), do: h >= 1.0
  defp airborne?(_st), do: false

  defp on_land_item?(%{ending: {:landing, seq}}, mission), do: mission.current == seq
  defp on_land_item?(_f, _mission), do: false

  defp progress(f, mission) do
    progress = %{reached: mission.reached, current: mission.current, total: mission.total}
    if f.active and progress != f.progress, do: {progress, %{f | progress: progress}}, else: {nil, f}
  end

  defp mode_name({:custom, n}), do: "mode #{n}"
  defp mode_name(mode), do: mode |> to_string() |> String.upcase()
end
