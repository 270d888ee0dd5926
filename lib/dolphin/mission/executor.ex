defmodule Dolphin.Mission.Executor do
  @moduledoc false
  # One running mission on one vehicle (the MAVLink platform's process; see
  # Dolphin.Mission.Platform for its contract with the engine).
  #
  # Start, as ArduCopter needs it (ARDUPILOT.md): hold the vehicle if it is
  # flying another mission; clear; upload; download it back and compare by
  # meaning (never start an unverified mission); GUIDED; arm, retried while the
  # autopilot is not ready, for at most `:arm_timeout_ms`; MISSION_START at once
  # (a copter armed on the ground disarms itself after ~10 s).
  #
  # Then it follows the vehicle's state: progress from MISSION_CURRENT /
  # MISSION_ITEM_REACHED, completion by how the mission ends (last item
  # reached; for a landing, landed and disarmed; never for an endless loiter),
  # and failure when the vehicle leaves AUTO or disarms before the end.
  #
  # Blocking steps (the mission and command protocols) run in a linked task so
  # that a stop is served at any moment. Stopping makes the vehicle hold
  # position: BRAKE, else GUIDED (never LOITER, which sinks without RC input),
  # or disarm when it is still on the ground.

  use GenServer, restart: :temporary

  alias Dolphin.{Mission, PubSub, Telemetry, Vehicles}
  alias Dolphin.Engine.Platform

  @arm_timeout_ms 120_000
  @landing_reports_ms 5_000
  @landing_modes [:rtl, :land, :smart_rtl, :auto_rtl]
  @takeoff 22
  @land 21
  # A landed vehicle this close to a mission's landing point is there.
  @here_m 5
  @arm_retry_ms 1_000
  @boot_timeout_ms 60_000
  @boot_poll_ms 200
  @transfer_attempts 3

  def start_link(mission, vehicle, opts), do: GenServer.start_link(__MODULE__, {mission, vehicle, Map.new(opts)})

  @doc false
  def stop(pid, reason), do: GenServer.call(pid, {:stop, reason}, :infinity)

  @impl true
  def init({%Mission{} = mission, vehicle, opts}) do
    # Linked to the engine's leaf: its exit means it died without stopping us.
    Process.flag(:trap_exit, true)
    PubSub.subscribe({:vehicle, vehicle})

    s = %{
      mission: mission,
      name: mission.name,
      vehicle: vehicle,
      owner: opts.owner,
      clock: Map.get(opts, :clock, Dolphin.Engine.TimeSource.Clock),
      arm_timeout_ms: Map.get(opts, :arm_timeout_ms, @arm_timeout_ms),
      items: nil,
      ending: nil,
      step: nil,
      task: nil,
      retransmissions: 0,
      started: false,
      active: false,
      armed_seen: false,
      auto_seen: false,
      landing_check: false,
      on_land_item: false,
      # The vehicle's STATUSTEXTs when the flight began (see autopilot_says/3).
      flight_texts: [],
      reached: nil,
      progress: nil
    }

    {:ok, s, {:continue, :start}}
  end

  @impl true
  def handle_continue(:start, s) do
    case items(s) do
      {:ok, items} -> {:noreply, run_step(%{s | items: items, ending: Mission.ending(items)}, :hold_if_flying)}
      {:error, why} -> fail(s, why)
    end
  end

  # The steps before the flight, in order; each runs in a task.
  @steps [:hold_if_flying, :clear, :upload, :verify, :guided, :arm, :start]

  defp run_step(s, step) do
    me = self()
    task = Task.async(fn -> step(step, s, me) end)
    %{s | step: step, task: task}
  end

  # The next step, or the flight once MISSION_START is accepted; a GenServer reply.
  defp next_step(s) do
    case Enum.drop_while(@steps, &(&1 != s.step)) do
      [_, next | _] -> {:noreply, run_step(s, next)}
      _ -> follow(%{s | step: :flying, task: nil, started: true, flight_texts: texts(s.vehicle)})
    end
  end

  @impl true
  def handle_info({ref, result}, %{task: %Task{ref: ref}} = s) do
    Process.demonitor(ref, [:flush])
    s = %{s | task: nil}

    case result do
      :ok ->
        next_step(s)

      :already_there ->
        Platform.done(s.owner)
        {:stop, :normal, s}

      {:uploaded, duration_ms} ->
        Telemetry.emit(:mission_uploaded, %{vehicle: s.vehicle, name: s.name, items: length(s.items), duration_ms: duration_ms, retransmissions: s.retransmissions})
        next_step(s)

      {:error, why} ->
        fail(s, why)
    end
  end

  def handle_info({:DOWN, ref, :process, _, reason}, %{task: %Task{ref: ref}} = s),
    do: fail(%{s | task: nil}, "#{s.step} crashed: #{Exception.format_exit(reason)}")

  def handle_info({:mission_done, :upload, %{retransmissions: n}}, s), do: {:noreply, %{s | retransmissions: n}}
  def handle_info({:mission_done, _, _}, s), do: {:noreply, s}
  def handle_info({:mission_progress, _, _, _}, s), do: {:noreply, s}

  # MISSION_CURRENT's ACTIVE may come and go between two reads of the state (a
  # mission that completes at once): the changes carried by the events count.
  def handle_info({:dolphin, {:vehicle, id}, {:state, id, changes}}, %{step: step} = s) when step in [:start, :flying] do
    s = if Enum.any?(changes, &match?({:mission, %{state: :active}}, &1)), do: %{s | active: true}, else: s
    if step == :flying, do: follow(s), else: {:noreply, s}
  end

  def handle_info({:dolphin, _topic, _event}, s), do: {:noreply, s}

  # A landing mission's disarm comes before its last report (ArduPilot reports
  # the final item after "Disarming motors"): give the reports their time.
  def handle_info(:check_landed, %{step: :flying} = s) do
    case Vehicles.state(s.vehicle) do
      {:ok, st} -> if complete?(s, st), do: done(s), else: fail(s, "the vehicle landed and disarmed before the mission's end (at item #{st.mission.current} of #{st.mission.total})")
      _ -> {:noreply, s}
    end
  end

  def handle_info(:check_landed, s), do: {:noreply, s}

  # The engine's leaf (our parent) exiting reaches terminate/2, not here.
  def handle_info({:EXIT, _pid, _reason}, s), do: {:noreply, s}
  def handle_info({:DOWN, _, :process, _, _}, s), do: {:noreply, s}

  # The engine's leaf died without stopping us: make the vehicle safe, then go.
  @impl true
  def terminate(:normal, _s), do: :ok

  def terminate(_reason, s) do
    cancel_task(s)
    _ = hold(s.vehicle, commanded?(s))
    :ok
  end

  @impl true
  def handle_call({:stop, {:vehicle_lost, _}}, _from, s) do
    # Nothing can be asked of a vehicle we cannot hear.
    cancel_task(s)
    {:stop, :normal, :ok, s}
  end

  def handle_call({:stop, _reason}, _from, s) do
    cancel_task(s)
    {:stop, :normal, hold(s.vehicle, commanded?(s)), s}
  end

  # Once arming or MISSION_START may have been accepted, the 1 Hz telemetry can
  # be older than the vehicle's state: a stop then assumes it may be flying.
  defp commanded?(s), do: s.started or s.step in [:arm, :start]

  # --- steps ------------------------------------------------------------------

  defp step(:hold_if_flying, s, _me) do
    case booted(s, s.clock.now_ms() + @boot_timeout_ms) do
      {:ok, %{armed: true, mode: :auto} = st} when st.landed != :on_ground -> hold(s.vehicle)
      {:ok, st} -> on_the_ground(s, st)
      {:error, _} = error -> error
    end
  end

  defp step(:clear, s, _me), do: mission_op(Vehicles.clear_mission(s.vehicle))

  defp step(:upload, s, me), do: upload(s, me, s.clock.now_ms(), @transfer_attempts)

  defp step(:verify, s, _me), do: verify(s, @transfer_attempts)

  defp step(:guided, s, _me) do
    case Vehicles.state(s.vehicle) do
      {:ok, %{mode: :guided}} -> :ok
      _ -> command(fn -> Vehicles.set_mode(s.vehicle, :guided) end, "switching to GUIDED", s.vehicle)
    end
  end

  defp step(:arm, s, _me), do: arm(s, s.clock.now_ms() + s.arm_timeout_ms, texts(s.vehicle))
  defp step(:start, s, _me), do: command(fn -> Vehicles.start_mission(s.vehicle) end, "MISSION_START", s.vehicle)

  # A copter on the ground can only start a mission that takes off (ArduCopter
  # refuses the others: "Auto: Missing Takeoff Cmd"). One that only comes back
  # and lands is already done when the vehicle stands at its landing point.
  defp on_the_ground(s, st) do
    takes_off? = Enum.any?(s.items, &(&1.command == @takeoff))
    grounded? = not st.armed and st.landed in [:on_ground, nil]

    cond do
      takes_off? or not grounded? -> :ok
      landing_here?(s, st) -> :already_there
      true -> {:error, "vehicle #{s.vehicle} is on the ground and the mission has no take-off"}
    end
  end

  defp landing_here?(%{ending: {:landing, seq}} = s, %{position: %{lat: lat, lon: lon}}) do
    item = Enum.at(s.items, seq)
    at = Dolphin.Geo.location(lat, lon)

    cond do
      item.command == @land and item.x != 0 -> Dolphin.Geo.distance(at, Dolphin.Geo.location(item.x / 1.0e7, item.y / 1.0e7)) <= @here_m
      true -> false
    end
  end

  defp landing_here?(_s, _st), do: false

  defp arm(s, deadline, before) do
    case Vehicles.state(s.vehicle) do
      {:ok, %{armed: true}} ->
        :ok

      _ ->
        case Vehicles.arm(s.vehicle) do
          {:ok, :accepted} ->
            :ok

          {:error, %{result: result}} when result in [:failed, :temporarily_rejected, :denied, :timeout] ->
            if s.clock.now_ms() >= deadline do
              {:error, "arming refused for #{div(s.arm_timeout_ms, 1000)} s#{autopilot_says(s.vehicle, before, ["Arm", "PreArm"])}"}
            else
              s.clock.sleep(@arm_retry_ms)
              arm(s, deadline, before)
            end

          {:error, e} ->
            {:error, "arming: #{Exception.message(e)}"}
        end
    end
  end

  # A transfer that timed out on a lossy link (the protocol's own retries ran
  # out) is started again from the beginning, a few times: only the vehicle's
  # refusals are final.
  defp upload(s, me, started, attempts) do
    # The protocol's counts ({:mission_done, ...}) go to the executor itself.
    case Vehicles.upload_mission(s.vehicle, s.items, progress_to: me) do
      :ok ->
        {:uploaded, s.clock.now_ms() - started}

      # Every item went out but the vehicle's final MISSION_ACK was lost (it is
      # never repeated): whether the vehicle has the mission is for the
      # verification, which downloads it, to say.
      {:error, %Dolphin.MissionError{result: :unconfirmed}} ->
        {:uploaded, s.clock.now_ms() - started}

      # The protocol starts a transaction again itself while the vehicle
      # answers; a vehicle silent for all of them may come back.
      {:error, %Dolphin.MissionError{result: result}} when result in [:timeout, :error] and attempts > 1 ->
        upload(s, me, started, attempts - 1)

      error ->
        mission_op(error)
    end
  end

  defp verify(s, attempts) do
    case Vehicles.download_mission(s.vehicle) do
      {:ok, back} ->
        case Mission.compare_download(s.items, back) do
          :ok -> :ok
          {:error, e} -> {:error, "the mission read back differs from the one uploaded: #{Exception.message(e)}"}
        end

      {:error, %Dolphin.MissionError{result: :timeout}} when attempts > 1 ->
        verify(s, attempts - 1)

      {:error, e} ->
        tried = @transfer_attempts - attempts + 1
        {:error, "reading the mission back to verify it failed#{if tried > 1, do: " (#{tried} attempts)"}: #{Exception.message(e)}"}
    end
  end

  # ArduCopter answers the mission protocol while it boots, before its mission
  # store is set up, refusing any upload with NO_SPACE: a vehicle that reports
  # MAV_STATE UNINIT or BOOT is waited for.
  defp booted(s, deadline) do
    case Vehicles.state(s.vehicle) do
      {:ok, st} ->
        cond do
          not Dolphin.Vehicles.State.booting?(st) ->
            {:ok, st}

          s.clock.now_ms() >= deadline ->
            {:error, "vehicle #{s.vehicle} was still booting after #{div(@boot_timeout_ms, 1000)} s (MAV_STATE #{if st.system_status == 0, do: "UNINIT", else: "BOOT"})"}

          true ->
            s.clock.sleep(@boot_poll_ms)
            booted(s, deadline)
        end

      {:error, :unknown_vehicle} ->
        {:error, not_mavlink(s)}
    end
  end

  # The fleet may be fake vehicles of the test platform (`--fake`), which the
  # ground station never hears: say so rather than "not connected".
  defp not_mavlink(s) do
    case Dolphin.Fleet.source() do
      {Dolphin.Fleet.TestSource, _} ->
        "mission #{inspect(s.name)} needs a MAVLink vehicle; vehicle #{s.vehicle} is a fake vehicle (--fake), which runs only test-platform tasks"

      _ ->
        "vehicle #{s.vehicle} is not connected"
    end
  end

  defp items(%{mission: mission, vehicle: vehicle}) do
    home =
      case {mission.home, Vehicles.state(vehicle)} do
        {nil, {:ok, %{home: %{lat: lat, lon: lon, alt: alt}}}} -> [home: Dolphin.Geo.location(lat, lon, alt)]
        _ -> []
      end

    {:ok, Mission.to_items(mission, home)}
  rescue
    e in ArgumentError -> {:error, "mission #{inspect(mission.name)} cannot be turned into items: #{Exception.message(e)}"}
  end

  defp mission_op(:ok), do: :ok
  defp mission_op({:error, e}), do: {:error, Exception.message(e)}

  # A command to the vehicle; refused, with what the autopilot said meanwhile.
  defp command(send, what, vehicle) do
    before = texts(vehicle)

    case send.() do
      {:ok, _} -> :ok
      {:error, e} -> {:error, "#{what} refused: #{Exception.message(e)}#{autopilot_says(vehicle, before, [])}"}
    end
  end

  defp texts(vehicle), do: Vehicles.status_texts(vehicle)

  # The autopilot's latest explanation (a STATUSTEXT of warning or worse, or
  # one with a prefix) among what it said since `before` (the texts when the
  # exchange began): a text from an hour ago answers nothing now.
  defp autopilot_says(vehicle, before, prefixes) do
    texts = Dolphin.Vehicles.State.texts_since(before, texts(vehicle))

    found =
      Enum.find(texts, fn {severity, text} ->
        Enum.any?(prefixes, &String.starts_with?(text, &1 <> ":")) or (prefixes == [] and severity <= 4)
      end)

    case found do
      {_, text} -> ": the autopilot says \"#{text}\""
      nil -> ""
    end
  end

  # --- flying -----------------------------------------------------------------

  defp follow(s) do
    case Vehicles.state(s.vehicle) do
      {:ok, st} -> judge(s, st)
      # Lost: the engine stops us with {:vehicle_lost, id}.
      {:error, _} -> {:noreply, s}
    end
  end

  defp judge(s, st) do
    mission = st.mission
    # The mission counts as running once the vehicle reports it active in AUTO,
    # or reports an item of it reached (progress restarts at every upload): a
    # mission that ends in the loop that starts it is only ever reported
    # COMPLETE, as ArduCopter sends the latest MISSION_CURRENT only. Before
    # that, the state still describes the previous mission.
    active = s.active or (st.mode == :auto and mission.state == :active) or mission.reached != nil
    # Reports travel separately (mode and armed bit with the 1 Hz heartbeat,
    # the mission state with MISSION_CURRENT): leaving AUTO or disarming counts
    # only once the heartbeat has shown AUTO, or armed, during this mission.
    s = %{s | active: active, armed_seen: s.armed_seen or (active and st.armed), auto_seen: s.auto_seen or (active and st.mode == :auto)}
    s = %{s | on_land_item: s.on_land_item or (active and st.armed and on_land_item?(s, mission))}
    # After its final landing ArduCopter resets the mission to item 1, often
    # before the heartbeat shows the disarm: that is no progress of this mission.
    s = if s.on_land_item and not on_land_item?(s, mission), do: s, else: report_progress(s, mission)

    cond do
      not active ->
        {:noreply, s}

      complete?(s, st) ->
        done(s)

      s.auto_seen and st.mode != :auto ->
        # Left to what took it (a failsafe's RTL or LAND, the pilot): never overridden.
        fail(s, "the vehicle left AUTO for #{mode_name(st.mode)} before the mission ended#{autopilot_says(s.vehicle, s.flight_texts, [])}", hold: false)

      s.armed_seen and not st.armed and not match?({:landing, _}, s.ending) ->
        fail(s, "the vehicle disarmed before the mission ended#{autopilot_says(s.vehicle, s.flight_texts, [])}", hold: false)

      s.armed_seen and not st.armed and not s.landing_check ->
        s.clock.send_after(self(), :check_landed, @landing_reports_ms)
        {:noreply, %{s | landing_check: true}}

      true ->
        {:noreply, s}
    end
  end

  # ArduPilot reports the end with MISSION_CURRENT state COMPLETE (after the
  # landing and disarm when the mission lands); `reached` of the last item
  # counts too, for autopilots without mission states.
  # ArduCopter reports a final RETURN_TO_LAUNCH reached after the disarm, but
  # a final NAV_LAND never: it disarms with the land item still current and
  # the mission ACTIVE (docs/ardupilot.md), so landed and disarmed at the last
  # item is the end.
  defp complete?(%{ending: {:landing, seq}} = s, st),
    do: s.armed_seen and not st.armed and (st.mission.state == :complete or st.mission.reached == seq or landed_at_end?(s, st, seq))

  defp complete?(%{ending: {:reached, seq}}, st), do: st.mission.state == :complete or (st.mission.state == nil and st.mission.reached == seq)
  defp complete?(_forever, _st), do: false

  # After that disarm ArduCopter resets its mission to item 1, often reported
  # before the heartbeat shows the disarm: what counts is that the vehicle
  # flew the final land item armed, then disarmed on the ground.
  defp landed_at_end?(s, st, _seq), do: s.on_land_item and st.landed in [:on_ground, nil]

  defp on_land_item?(%{ending: {:landing, seq}}, mission), do: mission.current == seq
  defp on_land_item?(_s, _mission), do: false

  defp report_progress(s, mission) do
    progress = %{reached: mission.reached, current: mission.current, total: mission.total}

    if s.active and progress != s.progress do
      Platform.progress(s.owner, progress)
      %{s | progress: progress}
    else
      s
    end
  end

  defp mode_name({:custom, n}), do: "mode #{n}"
  defp mode_name(mode), do: mode |> to_string() |> String.upcase()

  # --- stopping -----------------------------------------------------------------

  @doc false
  # Makes a vehicle safe: holding position in the air (BRAKE, else GUIDED),
  # disarmed on the ground, and left alone when its autopilot is bringing it
  # down (RTL, LAND: a failsafe or the pilot decided). `fresh?`: the state may
  # be older than commands just accepted (arming, MISSION_START), so the
  # vehicle is held as if flying whatever the telemetry says.
  @spec hold(byte(), boolean()) :: :ok | {:error, String.t()}
  def hold(vehicle, fresh? \\ false) do
    case Vehicles.state(vehicle) do
      {:error, :unknown_vehicle} -> :ok
      {:ok, %{mode: mode}} when mode in @landing_modes -> :ok
      {:ok, %{armed: false}} when not fresh? -> :ok
      {:ok, %{mode: mode}} when mode in [:brake, :guided] and not fresh? -> :ok
      {:ok, %{landed: :on_ground}} when not fresh? -> disarm_or_brake(vehicle)
      {:ok, _} -> brake(vehicle)
    end
  end

  # An accepted DO_SET_MODE means the mode has changed (ArduPilot acks after
  # the switch); the heartbeat shows it within a second.
  defp brake(vehicle) do
    with {:error, _} <- command(fn -> Vehicles.set_mode(vehicle, :brake) end, "BRAKE", vehicle),
         {:error, why} <- command(fn -> Vehicles.set_mode(vehicle, :guided) end, "GUIDED", vehicle) do
      {:error, "the vehicle could not be made to hold position: #{why}"}
    end
  end

  # "On the ground" may be a second old: a vehicle that refuses the disarm is flying.
  defp disarm_or_brake(vehicle) do
    case command(fn -> Vehicles.disarm(vehicle) end, "disarming on the ground", vehicle) do
      :ok -> :ok
      {:error, _} -> brake(vehicle)
    end
  end

  defp cancel_task(%{task: nil}), do: :ok
  defp cancel_task(%{task: task}), do: Task.shutdown(task, :brutal_kill) && :ok

  defp done(s) do
    Platform.done(s.owner)
    {:stop, :normal, s}
  end

  defp fail(s, why, opts \\ []) do
    # The engine says which task and which vehicle; the reason says what happened.
    Platform.failed(s.owner, why)
    # A failed mission leaves the vehicle holding, not flying on.
    _ = if Keyword.get(opts, :hold, true) and commanded?(s), do: hold(s.vehicle, true)
    {:stop, :normal, s}
  end
end
