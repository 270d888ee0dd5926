defmodule Dolphin.Mission.Executor do
  @moduledoc false
  # One running mission on one vehicle (the MAVLink platform's process; see
  # Dolphin.Mission.Platform for its contract with the engine), a :gen_statem
  # over the steps ArduCopter needs (docs/ardupilot.md):
  #
  #   :hold -> :clear -> :upload -> :verify -> [:fence] -> :guided -> :arm -> :start -> :flying -> done | failed
  #
  # (:verify goes back to :upload when an unconfirmed upload reads back
  # otherwise; :flying back to :guided when the autopilot disarmed the
  # vehicle on the ground before its flight began.)
  #
  # :hold waits for the end of the vehicle's boot and holds it if it is flying
  # another mission; then clear; upload; download it back and compare by
  # meaning (never start an unverified mission); the mission's fence, or the
  # script's, put on the vehicle (Dolphin.Vehicles.Fences); GUIDED; arm, retried while the
  # autopilot is not ready, for at most `:arm_timeout_ms`; MISSION_START at once
  # (a copter armed on the ground disarms itself after ~10 s). In :flying it
  # follows the vehicle's state (Dolphin.Mission.Executor.Flight judges it);
  # a vehicle that stays armed on the ground, where it stood, for a minute
  # of clock time (a take-off that does not climb) fails the task rather
  # than leave it waiting for ever.
  # Every state ends in the next one or, done or failed, in a report to the
  # engine (Dolphin.Engine.Platform.done/1, failed/2) and a normal exit.
  #
  # A step's exchange with the vehicle (the mission and command protocols,
  # the manoeuvres of Dolphin.Vehicles.Manoeuvres) blocks until the vehicle
  # answers, so it runs in a linked task whose result is the state's event:
  # a stop is served at any moment. Stopping makes the vehicle hold position
  # (Dolphin.Vehicles.Manoeuvres.hold/2). Timers are in Dolphin.Clock time,
  # the vehicles' time (the engine's `:clock` option times the engine only).

  @behaviour :gen_statem

  alias Dolphin.{Airframe, Clock, Mission, Events, Vehicles}
  alias Dolphin.Engine.Platform
  alias Dolphin.Mission.Executor.Flight
  alias Dolphin.Vehicles.Manoeuvres

  @arm_timeout_ms 120_000
  @landing_reports_ms 5_000
  # And never under this much real time: the reports cross a host that may
  # be busy (at 50x, 5 s of clock are 100 ms, and a loaded host delivered a
  # simulated copter's final item reached later than that). The wait ends as
  # soon as they come; this only bounds a wait for reports that never do.
  @landing_reports_floor_real_ms 2_000
  # How long (clock ms) a vehicle that left its mission is given to say why.
  @reason_ms 1_000
  @takeoff 22
  @land 21
  @return_to_launch 20
  # A landed vehicle this close to a mission's landing point is there.
  @here_m 5
  @boot_timeout_ms 60_000
  # Armed on the ground in a mission this long, the vehicle is not taking
  # off: ArduCopter spools up in about 2 s and then climbs its first metre
  # (docs/ardupilot.md); a copter held armed there by a delay disarms
  # itself after 10 s (DISARM_DELAY).
  @grounded_timeout_ms 60_000
  # And never under this much real time: a simulation sped up on a busy
  # host falls behind its clock (a simulated copter beside SITL fleets and
  # busy loops stood "armed on the ground" for 60 s of clock, 6 s of real
  # time at 10x, while it was merely late), not a real vehicle at 1x.
  @grounded_floor_real_ms 15_000
  # Armed for its take-off, then seen disarmed on the ground before the
  # flight began: ArduCopter disarms a copter armed without taking off
  # after DISARM_DELAY (10 s), which a slow, lossy link can let pass between
  # the arm and MISSION_START (seen on the simulator over 30 % loss on a
  # loaded machine: the start came 20 s of clock time after the arm). After
  # this grace (a view may lag the arm), the vehicle is set to GUIDED, armed
  # and started again, at most @rearms times.
  @rearm_grace_ms 5_000
  @rearm_grace_floor_real_ms 2_000
  @rearms 3
  # Standing still this long (clock ms) short of a waypoint in AUTO, the
  # vehicle is stuck: ArduRover stops short of its fence and says nothing.
  @stuck_timeout_ms 60_000
  # Still: within this many metres of where it stood; short of its
  # waypoint: farther than this from it.
  @still_m 1.0
  @short_m 10.0
  @waypoint 16
  # Below this height above home, with no landed state saying otherwise, the vehicle is on the ground.
  @ground_m 1.0
  @boot_poll_ms 200
  @transfer_attempts 3

  # The process's data. `leaving`: why the vehicle left its mission (a
  # failsafe, the pilot), while it is given the time to say so. `fence`: its
  # own, else the script's (the run's platform options). `started_at` (clock
  # ms; of two vehicles about to come too close, the later one's holds),
  # `rank` and `min_separation` (nil: the default) are for
  # Dolphin.Separation; `separation`: nil, or what the monitor wants (:hold,
  # :go) and how far the vehicle is (:holding, :held, :resuming, :resumed
  # until a view shows AUTO again); `held_on_ground`: held by it before it
  # left the ground, in this flight. `airframe`: how its missions fly
  # (Dolphin.Vehicles.View.airframe/2), from its view once known.
  # `grounded`: where the vehicle was first seen armed on the ground in
  # :flying, while it stays so; `disarmed_idle`: seen disarmed on the ground
  # in :flying before its flight began (a timer runs); `rearms`: how many
  # times it was armed and started again; `restarted`: started again at
  # least once (GUIDED is then asked for whatever the view says); `still`: where and at which item it
  # was first seen standing still short of a waypoint in :flying, while it
  # stays so. `task` and `attempt`: the exchange of the current step, and the
  # how-manieth try of it. `unconfirmed`: uploads in a row that ended without
  # the vehicle's final ACCEPTED (every item sent; whether it holds the
  # mission is for the read-back). `flight_texts`: the vehicle's STATUSTEXTs
  # when the flight began (see judge/2). `view`: the last view of the vehicle
  # it was sent (:start, :flying): the flight is judged on the views in the
  # order they came, never on a read of the table, which can be newer than
  # views still waiting in the mailbox.
  defstruct [
    :mission,
    :name,
    :fence,
    :vehicle,
    :owner,
    :started_at,
    :rank,
    :min_separation,
    :arm_timeout_ms,
    :boot_deadline,
    leaving: nil,
    separation: nil,
    held_on_ground: false,
    airframe: nil,
    grounded: nil,
    disarmed_idle: false,
    rearms: 0,
    restarted: false,
    still: nil,
    items: nil,
    ending: nil,
    task: nil,
    attempt: 1,
    upload_started: nil,
    retransmissions: 0,
    unconfirmed: 0,
    flight_texts: [],
    flight: nil,
    view: nil
  ]

  @typedoc false
  @type t :: %__MODULE__{
          mission: Mission.t(),
          name: String.t() | nil,
          fence: Dolphin.Fence.t() | nil,
          vehicle: Dolphin.Vehicles.Id.t(),
          owner: pid() | nil,
          started_at: integer(),
          rank: {term(), term()},
          min_separation: number() | nil,
          arm_timeout_ms: non_neg_integer(),
          boot_deadline: integer(),
          leaving: term(),
          separation: map() | nil,
          held_on_ground: boolean(),
          airframe: Dolphin.Airframe.t() | nil,
          grounded: term(),
          disarmed_idle: boolean(),
          rearms: non_neg_integer(),
          restarted: boolean(),
          still: term(),
          items: [struct()] | nil,
          ending: term(),
          task: Task.t() | nil,
          attempt: pos_integer(),
          upload_started: integer() | nil,
          retransmissions: non_neg_integer(),
          unconfirmed: non_neg_integer(),
          flight_texts: [{integer(), String.t()}],
          flight: Flight.t() | nil,
          view: Dolphin.Vehicles.View.t() | nil
        }

  # `opts`: the platform's, and `:debug`, `:gen_statem`'s debug options
  # (`:sys`), in effect from its first event.
  @spec start_link(Mission.t(), byte(), keyword()) :: :gen_statem.start_ret()
  def start_link(mission, vehicle, opts) do
    {debug, opts} = Keyword.pop(opts, :debug, [])
    :gen_statem.start_link(__MODULE__, {mission, vehicle, Map.new(opts)}, debug: debug)
  end

  @doc false
  # Returns once the vehicle is safe: :ok, or {:error, why} when it could not be made to hold.
  @spec stop(pid(), term()) :: :ok | {:error, String.t()}
  def stop(pid, reason), do: :gen_statem.call(pid, stop_request(reason), :infinity)

  @doc false
  # The call stop/2 makes, for a caller that sends it as a request of its own (the engine's leaf).
  @spec stop_request(term()) :: {:stop, term()}
  def stop_request(reason), do: {:stop, reason}

  @impl true
  def callback_mode, do: [:handle_event_function, :state_enter]

  @impl true
  def init({%Mission{} = mission, vehicle, opts}) do
    # Linked to the engine's leaf: its exit means it died without stopping us.
    Process.flag(:trap_exit, true)
    # Its views: every change of what the vehicle reports, in order, read
    # from the message itself (no call to the vehicle's process).
    Vehicles.subscribe(vehicle)

    data = %__MODULE__{
      mission: mission,
      name: mission.name,
      fence: mission.fence || Map.get(opts, :fence),
      vehicle: vehicle,
      owner: opts.owner,
      started_at: Clock.now_ms(),
      rank: {Map.get(opts, :run), Map.get(opts, :task_id)},
      min_separation: Map.get(opts, :min_separation),
      arm_timeout_ms: Map.get(opts, :arm_timeout_ms, @arm_timeout_ms),
      boot_deadline: Clock.now_ms() + @boot_timeout_ms
    }

    {:ok, :hold, data}
  end

  # --- entering a step ----------------------------------------------------------

  @impl true
  # At once: the first look at the vehicle needs no wait. (Its items are
  # made once it is known: they depend on its airframe, and on its home
  # when the mission gives none.)
  def handle_event(:enter, _old, :hold, data), do: {:keep_state, data, [{:state_timeout, 0, :look}]}

  def handle_event(:enter, _old, :clear, data), do: exchange(data, fn -> Vehicles.clear_mission(data.vehicle) end)

  def handle_event(:enter, _old, :upload, data) do
    me = self()
    data = %{data | upload_started: data.upload_started || Clock.now_ms()}
    # The protocol's counts ({:mission_done, ...}) come to the executor itself.
    exchange(data, fn -> Vehicles.upload_mission(data.vehicle, data.items, progress_to: me) end)
  end

  def handle_event(:enter, _old, :verify, data), do: exchange(data, fn -> Vehicles.download_mission(data.vehicle) end)

  def handle_event(:enter, _old, :fence, data) do
    home = fence_home(data)
    exchange(data, fn -> Dolphin.Vehicles.Fences.apply(data.vehicle, data.fence, home, data.airframe) end)
  end

  # After a restart, GUIDED is asked for whatever the view says: the resume
  # from a separation hold may have had AUTO accepted just before the
  # autopilot disarmed the copter, and a view still in GUIDED left it to be
  # armed in AUTO, refused for the whole arming bound ("AUTO mode not armable").
  def handle_event(:enter, _old, :guided, data),
    do: exchange(data, fn -> Manoeuvres.guided(data.vehicle, within: data.arm_timeout_ms, force: data.restarted) end)
  def handle_event(:enter, _old, :arm, data), do: exchange(data, fn -> Manoeuvres.arm_when_ready(data.vehicle, within: data.arm_timeout_ms) end)

  def handle_event(:enter, _old, :start, data),
    do: exchange(data, fn -> Manoeuvres.command(data.vehicle, "MISSION_START", fn -> Vehicles.start_mission(data.vehicle) end) end)

  def handle_event(:enter, _old, :flying, data) do
    data = %{data | flight_texts: Vehicles.status_texts(data.vehicle)}
    :ok = Dolphin.Separation.flying(data.vehicle, started_at: data.started_at, rank: data.rank, limits: data.min_separation)
    # Flying again after a restart: what the monitor sent before it took
    # the registration (it replies after) is about the flight before.
    flush_separation()
    # Judged at once on what it was last sent; else on the next view.
    if data.view, do: judge(data, data.view), else: {:keep_state, data}
  end

  # --- :hold: booted, and not flying another mission -----------------------------

  def handle_event(:state_timeout, :look, :hold, data) do
    case Vehicles.view(data.vehicle) do
      {:ok, st} ->
        cond do
          # A mission without a home flies from the vehicle's, which it
          # reports once its position estimate has an origin (ArduSub and
          # ArduPlane a while after boot): waited for as the boot is.
          data.items == nil and data.mission.home == nil and st.home == nil and Clock.now_ms() < data.boot_deadline ->
            {:keep_state_and_data, [{:state_timeout, Clock.to_real_ms(@boot_poll_ms), :look}]}

          data.items == nil ->
            with_items(data, st)

          not Dolphin.Vehicles.State.booting?(st) ->
            look(data, st)

          Clock.now_ms() >= data.boot_deadline ->
            fail(:hold, data, {:booting, if(st.system_status == 0, do: :uninit, else: :boot), div(@boot_timeout_ms, 1000)})

          # ArduCopter answers the mission protocol while it boots, before its
          # mission store is set up, refusing any upload with NO_SPACE: a
          # vehicle that reports MAV_STATE UNINIT or BOOT is looked at again.
          true ->
            {:keep_state_and_data, [{:state_timeout, Clock.to_real_ms(@boot_poll_ms), :look}]}
        end

      {:error, :unknown_vehicle} ->
        fail(:hold, data, :not_connected)
    end
  end

  # --- a step's exchange ended ------------------------------------------------

  def handle_event(:info, {ref, result}, state, %{task: %Task{ref: ref}} = data) do
    Process.demonitor(ref, [:flush])
    answered(state, result, %{data | task: nil})
  end

  def handle_event(:info, {:DOWN, ref, :process, _, reason}, state, %{task: %Task{ref: ref}} = data),
    do: fail(state, %{data | task: nil}, {:exchange_crashed, reason})

  def handle_event(:info, {:mission_done, :upload, %{retransmissions: n}}, _state, data), do: {:keep_state, %{data | retransmissions: n}}
  def handle_event(:info, {:mission_done, _, _}, _state, _data), do: :keep_state_and_data
  def handle_event(:info, {:mission_progress, _, _, _}, _state, _data), do: :keep_state_and_data

  # --- :start and :flying: the vehicle's state ----------------------------------

  # Left to what took it, and saying why: nothing more to judge.
  def handle_event(:info, {:dolphin, {:vehicle, id}, {:view, st}}, :flying, %{vehicle: id, leaving: cause} = data) when cause != nil,
    do: {:keep_state, %{data | view: st}}

  def handle_event(:info, {:dolphin, {:vehicle, id}, {:view, st}}, state, %{vehicle: id} = data) when state in [:start, :flying] do
    data = %{data | view: st, flight: Flight.reported(data.flight, st)}
    # While MISSION_START's answer is awaited, what the vehicle shows is kept for the judging.
    if state == :flying, do: judge(data, st), else: {:keep_state, %{data | flight: Flight.observe(data.flight, st)}}
  end

  def handle_event(:info, {:dolphin, _topic, _event}, _state, _data), do: :keep_state_and_data

  # --- :flying: held apart from another vehicle (Dolphin.Separation) ---------------

  # (A vehicle leaving its mission to a failsafe is left to it.)
  def handle_event(:info, {:separation, :hold, _seen}, :flying, %{leaving: nil} = data), do: separation(data, :hold)
  def handle_event(:info, {:separation, :clear, _}, :flying, %{leaving: nil} = data), do: separation(data, :go)

  # Held and still in the other's way: a copter moves up (or down) out of it.
  def handle_event(:info, {:separation, :aside, %{metres: m}}, :flying, %{leaving: nil, separation: %{phase: :held, want: :hold}, task: nil} = data) do
    case aside_point(data, m) do
      nil -> :keep_state_and_data
      point -> exchange(put_in(data.separation.phase, :aside), fn -> Manoeuvres.go_to(data.vehicle, point) end)
    end
  end

  def handle_event(:info, {:separation, _, _}, _state, _data), do: :keep_state_and_data

  def handle_event({:timeout, :grounded}, :grounded, :flying, %{view: st} = data) do
    if still_grounded?(data, st),
      do: fail(:flying, data, grounded(data, st), vehicle_fault?: true, texts: texts(data)),
      else: judge(%{data | grounded: nil}, st)
  end

  def handle_event({:timeout, :disarmed}, :disarmed, :flying, %{view: st} = data) do
    cond do
      not disarmed_before_flight?(data, st) -> judge(%{data | disarmed_idle: false}, st)
      data.rearms < @rearms -> restart(data, :disarmed_before_start)
      true -> fail(:flying, data, disarmed_before_start(data), vehicle_fault?: true, texts: texts(data))
    end
  end

  def handle_event({:timeout, :stuck}, :stuck, :flying, %{view: st} = data) do
    case stuck(data, st) do
      {:stuck, cause} -> fail(:flying, data, cause, texts: texts(data))
      :moving -> judge(%{data | still: nil}, st)
    end
  end

  def handle_event(:state_timeout, :said, :flying, %{leaving: cause} = data),
    do: fail(:flying, data, cause, vehicle_fault?: true, texts: texts(data), hold: false)

  def handle_event(:state_timeout, :check_landed, :flying, data) do
    case Vehicles.view(data.vehicle) do
      {:ok, st} ->
        if disarmed_after_arming?(data, st) do
          disarmed_before_take_off(data, st)
        else
          case Flight.landed(data.flight, st) do
            :done -> done(data)
            {:failed, cause} -> fail(:flying, data, cause)
          end
        end

      _ ->
        :keep_state_and_data
    end
  end

  # --- stopping ---------------------------------------------------------------

  def handle_event({:call, from}, {:stop, {:vehicle_lost, _}}, _state, data) do
    # Nothing can be asked of a vehicle we cannot hear.
    cancel_task(data)
    {:stop_and_reply, :normal, [{:reply, from, :ok}]}
  end

  def handle_event({:call, from}, {:stop, _reason}, state, data) do
    cancel_task(data)
    # (A vehicle that left its mission to a failsafe is not held: never overridden.)
    reply = if data.leaving, do: :ok, else: hold(data.vehicle, commanded?(state))
    {:stop_and_reply, :normal, [{:reply, from, reply}]}
  end

  # A task's exit comes with its :DOWN; the engine's leaf (our parent) exiting
  # reaches terminate/3, not here.
  def handle_event(:info, {:EXIT, _pid, _reason}, _state, _data), do: :keep_state_and_data
  def handle_event(:info, {:DOWN, _, :process, _, _}, _state, _data), do: :keep_state_and_data

  # The engine's leaf died without stopping us: make the vehicle safe, then go.
  @impl true
  def terminate(:normal, _state, _data), do: :ok

  def terminate(_reason, state, data) do
    cancel_task(data)
    _ = hold(data.vehicle, commanded?(state))
    :ok
  end

  # Once arming or MISSION_START may have been accepted, the 1 Hz telemetry can
  # be older than the vehicle's state: a stop then assumes it may be flying.
  defp commanded?(state), do: state in [:arm, :start, :flying]

  defp flush_separation do
    receive do
      {:separation, _, _} -> flush_separation()
    after
      0 -> :ok
    end
  end

  # A hold that failed is told to the engine as the manoeuvre's error (data,
  # worded where it is shown).
  defp hold(vehicle, fresh?), do: Manoeuvres.hold(vehicle, fresh: fresh?)

  # --- steps ------------------------------------------------------------------

  # Runs a step's exchange in a linked task; its result comes as an event.
  defp exchange(data, fun), do: {:keep_state, %{data | task: Task.async(fun)}}

  defp next(state, data), do: {:next_state, state, %{data | attempt: 1}}

  # The vehicle flies another mission: it holds first (ArduCopter refuses to
  # clear a mission that runs in AUTO).
  defp look(data, %{armed?: true, mode: :auto} = st) when st.landed != :on_ground,
    do: exchange(data, fn -> Manoeuvres.hold(data.vehicle) end)

  defp look(data, st) do
    case on_the_ground(data, st) do
      :ok -> next(:clear, data)
      :already_there -> done(data)
      {:error, cause} -> fail(:hold, data, cause)
    end
  end

  # The mission's home: rally heights are above it.
  defp fence_home(%{items: [home | _]}), do: Dolphin.Geo.location(home.x / 1.0e7, home.y / 1.0e7, home.z)

  # What the exchange of `state` answered; the next step, or the end.
  defp answered(:flying, result, %{separation: %{phase: phase}} = data) when phase in [:holding, :aside, :resuming], do: separated(result, data)
  defp answered(:hold, :ok, data), do: next(:clear, data)
  defp answered(:clear, :ok, data), do: next(:upload, data)

  defp answered(:upload, :ok, data), do: uploaded(%{data | unconfirmed: 0})

  # Every item went out but the vehicle's final MISSION_ACK was lost (it is
  # never repeated): whether the vehicle has the mission is for the
  # verification, which downloads it, to say.
  defp answered(:upload, {:error, %Dolphin.MissionError{result: :unconfirmed}}, data), do: uploaded(%{data | unconfirmed: data.unconfirmed + 1})

  # A transfer that timed out on a lossy link (the protocol's own retries ran
  # out; it starts a transaction again itself while the vehicle answers) is
  # started again from the beginning, a few times: only the vehicle's
  # refusals are final.
  defp answered(:upload, {:error, %Dolphin.MissionError{result: result}}, data) when result in [:timeout, :error] and data.attempt < @transfer_attempts,
    do: {:repeat_state, %{data | attempt: data.attempt + 1}}

  defp answered(:verify, {:ok, back}, data) do
    case Mission.compare_download(data.items, back) do
      :ok ->
        next(if(data.fence, do: :fence, else: :guided), data)

      # Unconfirmed, the upload may have been given up by the vehicle (its
      # cancel lost too, on a host too busy to tell the two apart by time):
      # uploaded again, a few times.
      {:error, _} when data.unconfirmed in 1..(@transfer_attempts - 1) ->
        next(:upload, data)

      {:error, e} ->
        fail(:verify, data, {:read_back_differs, e})
    end
  end

  defp answered(:verify, {:error, %Dolphin.MissionError{result: :timeout}}, data) when data.attempt < @transfer_attempts,
    do: {:repeat_state, %{data | attempt: data.attempt + 1}}

  defp answered(:verify, {:error, e}, data),
    do: fail(:verify, data, {:read_back_failed, e, data.attempt})

  defp answered(:fence, :ok, data) do
    items = Dolphin.Fence.to_items(data.fence, fence_home(data))

    Events.emit(:fence_applied, %{
      vehicle: data.vehicle,
      name: data.name,
      fence: for(i <- items.fence, do: [i.command, i.x, i.y, i.param1]),
      rally: for(i <- items.rally, do: [i.x, i.y, i.z])
    })

    next(:guided, data)
  end

  defp answered(:fence, {:error, e}, data), do: fail(:fence, data, {:refused, e})
  defp answered(:guided, :ok, data), do: next(:arm, data)
  defp answered(:arm, :ok, data), do: next(:start, data)
  # The autopilot would not arm (not ready, a failed check): the vehicle's own fault.
  defp answered(:arm, {:error, e}, data), do: fail(:arm, data, {:refused, e}, vehicle_fault?: true)
  defp answered(:start, :ok, data), do: next(:flying, data)

  # Refused: a copter that touched down since the mission was looked at (its
  # landing was under way, as a stopped mission leaves one) has no take-off
  # to fly; one that only comes back and lands is done if it stands there.
  # Never answered, MISSION_START may still have been taken: an autopilot
  # whose link to us is full drops its COMMAND_ACK (ArduPilot sends none
  # when the link has no room). A vehicle that reported this mission
  # running meanwhile (the views while the answer was awaited) flies it: it
  # is followed as started, and judged at once on what it showed.
  defp answered(:start, {:error, %{refusal: %Dolphin.CommandError{result: :timeout}}}, %{flight: %Flight{active: true}} = data), do: next(:flying, data)

  defp answered(:start, {:error, e}, data) do
    case Vehicles.view(data.vehicle) do
      {:ok, st} -> if on_the_ground(data, st) == :already_there, do: done(data), else: fail(:start, data, {:refused, e})
      _ -> fail(:start, data, {:refused, e})
    end
  end

  defp answered(state, {:error, e}, data), do: fail(state, data, {:refused, e})

  defp uploaded(data) do
    Events.emit(:mission_uploaded, %{
      vehicle: data.vehicle,
      name: data.name,
      items: length(data.items),
      duration_ms: Clock.now_ms() - data.upload_started,
      retransmissions: data.retransmissions
    })

    next(:verify, data)
  end

  # A copter on the ground can only start a mission that takes off (ArduCopter
  # refuses the others: "Auto: Missing Takeoff Cmd"), armed or not (one just
  # landed is armed until it disarms). One that only comes back and lands is
  # already done when the vehicle stands at its landing point.
  # (A rover, boat or submarine starts where it is.)
  defp on_the_ground(data, st) do
    takes_off? = Enum.any?(data.items, &(&1.command == @takeoff))
    grounded? = st.landed == :on_ground or (not st.armed? and st.landed == nil)

    cond do
      not Airframe.takes_off?(data.airframe) -> :ok
      takes_off? or not grounded? -> :ok
      landing_here?(data, st) -> :already_there
      true -> {:error, :no_take_off}
    end
  end

  defp landing_here?(%{ending: {:landing, seq}} = data, %{position: %{lat: lat, lon: lon}} = st) do
    item = Enum.at(data.items, seq)
    at = Dolphin.Geo.location(lat, lon)

    cond do
      item.command == @land and item.x != 0 -> Dolphin.Geo.distance(at, Dolphin.Geo.location(item.x / 1.0e7, item.y / 1.0e7)) <= @here_m
      # A return lands at home, unless a rally point is nearer (then it is not known here).
      item.command == @return_to_launch and st.home != nil and rally_points(data) == [] -> Dolphin.Geo.distance(at, st.home) <= @here_m
      true -> false
    end
  end

  defp landing_here?(_data, _st), do: false

  defp rally_points(%{fence: %Dolphin.Fence{rally: rally}}), do: rally
  defp rally_points(_data), do: []

  # The items for this vehicle (its airframe, its home), then a look at it again at once.
  defp with_items(data, st) do
    data = %{data | airframe: st.airframe}

    case items(data, st) do
      {:ok, items} ->
        ending = Mission.ending(items, data.airframe)
        {:keep_state, %{data | items: items, ending: ending, flight: Flight.new(ending)}, [{:state_timeout, 0, :look}]}

      {:error, cause} ->
        fail(:hold, data, cause)
    end
  end

  defp items(%{mission: mission, airframe: airframe}, st) do
    home =
      case {mission.home, st.home} do
        {nil, %Dolphin.Geo.Location{} = home} -> [home: home]
        _ -> []
      end

    {:ok, Mission.to_items(mission, [airframe: airframe] ++ home)}
  rescue
    e in ArgumentError -> {:error, {:cannot_make_items, Exception.message(e)}}
  end

  # --- :flying: separation holds ---------------------------------------------------

  # What the monitor wants now; one exchange with the vehicle at a time,
  # the next one once it ends.
  defp separation(%{separation: nil} = data, :hold),
    do: separation_step(%{data | separation: %{want: :hold, phase: :resumed}, held_on_ground: data.held_on_ground or not data.flight.airborne_seen})

  defp separation(%{separation: nil} = data, :go), do: {:keep_state, data}
  defp separation(data, want), do: separation_step(put_in(data.separation.want, want))

  defp separation_step(%{separation: %{want: :hold, phase: :resumed}} = data),
    do: exchange(put_in(data.separation.phase, :holding), fn -> Manoeuvres.hold(data.vehicle, fresh: true) end)

  defp separation_step(%{separation: %{want: :go, phase: :held}} = data) do
    if disarmed_held?(data, data.view),
      do: restart(data, :disarmed_while_held),
      else: exchange(put_in(data.separation.phase, :resuming), fn -> Manoeuvres.command(data.vehicle, "AUTO", fn -> Vehicles.set_mode(data.vehicle, :auto) end) end)
  end

  defp separation_step(data), do: {:keep_state, data}

  defp separated(:ok, %{separation: %{phase: phase}} = data) when phase in [:holding, :aside], do: separation_step(put_in(data.separation.phase, :held))
  # Moving aside is for good measure: refused (the vehicle touched down meanwhile), it holds where it is.
  defp separated({:error, _}, %{separation: %{phase: :aside}} = data), do: separation_step(put_in(data.separation.phase, :held))

  # Disarmed on the ground while its AUTO was on the way: whatever the answer, started again.
  defp separated(result, %{separation: %{phase: :resuming}} = data) do
    cond do
      disarmed_held?(data, data.view) -> restart(data, :disarmed_while_held)
      result == :ok -> separation_step(put_in(data.separation.phase, :resumed))
      true -> separated_failed(result, data)
    end
  end

  defp separated(result, data), do: separated_failed(result, data)

  defp separated_failed({:error, e}, data), do: fail(:flying, data, {:refused, e})

  # Where a held copter goes out of the other's way: `m` metres up, or down
  # when its fence's ceiling is nearer; nil when neither keeps 5 m clear of
  # the ceiling, the floor and the ground (or it is not a copter).
  defp aside_point(%{airframe: airframe, view: %{position: %{lat: lat, lon: lon}, relative_altitude: h}} = data, m) when is_number(h) do
    ceiling = if data.fence && data.fence.max_altitude, do: data.fence.max_altitude - 5, else: nil
    floor = max(5, if(data.fence && data.fence.min_altitude, do: data.fence.min_altitude + 5, else: 5))

    cond do
      airframe != :copter -> nil
      ceiling == nil or h + m <= ceiling -> {lat, lon, h + m}
      h - m >= floor -> {lat, lon, h - m}
      true -> nil
    end
  end

  defp aside_point(_data, _m), do: nil

  # Held by the monitor, the vehicle is in a mode that holds it: no leaving
  # of its mission. It is back in it once a view shows AUTO after the resume.
  defp separated_verdict(%{separation: nil}, _st, verdict), do: verdict

  defp separated_verdict(data, st, {:left, {:left_auto, _}} = verdict),
    do: if(st.mode in Manoeuvres.hold_modes(data.airframe), do: :flying, else: verdict)

  defp separated_verdict(_data, _st, verdict), do: verdict

  defp back_in_mission(%{separation: %{phase: :resumed, want: :go}} = data, %{mode: :auto}), do: %{data | separation: nil}
  defp back_in_mission(data, _st), do: data

  # Held by the monitor before it left the ground, a copter stands there
  # armed in BRAKE (or LOITER), which holds nothing on the ground: ArduCopter
  # disarms it after DISARM_DELAY (docs/ardupilot.md). It has not left its
  # mission: it waits, disarmed, and once let go it is set to GUIDED, armed
  # and started again (the mission resumes at its take-off). Only in the
  # mode it was held in (or AUTO, let go): a pilot or a failsafe that took
  # it to another is left alone. Each restart needs the monitor to let go
  # after a hold: they cannot run away on their own. Let go, its AUTO may
  # still find it disarmed (ArduCopter's DISARM_DELAY runs on until the
  # motors spool up again: held for 9.9 s, released as it ran out, a copter
  # was disarmed in AUTO): held on the ground once, it is judged so until
  # it is seen in the air. Judged on its latest view (nil: none yet).
  defp disarmed_held?(_data, nil), do: false

  defp disarmed_held?(%{held_on_ground: true, flight: flight, airframe: :copter}, st),
    do: not flight.airborne_seen and disarmed_on_ground?(st) and st.mode in [:auto | Manoeuvres.hold_modes(:copter)]

  defp disarmed_held?(_data, _st), do: false

  # Disarmed on the ground before the flight began: set to GUIDED, armed and
  # started again, its watchdogs stopped (they are the flight's).
  defp restart(data, reason) do
    Events.emit(:mission_restarted, %{vehicle: data.vehicle, name: data.name, reason: reason})
    rearms = if reason == :disarmed_before_start, do: data.rearms + 1, else: data.rearms
    data = %{data | separation: nil, held_on_ground: false, flight: Flight.new(data.ending), disarmed_idle: false, grounded: nil, still: nil, rearms: rearms, restarted: true}
    {:next_state, :guided, %{data | attempt: 1}, cancel_watches()}
  end

  # The flight's watchdogs (see judge_flight/2): stopped while it waits held, and before a restart.
  defp cancel_watches, do: for(t <- [:grounded, :disarmed, :stuck], do: {{:timeout, t}, :cancel})

  # --- :flying ----------------------------------------------------------------

  defp judge(data, st) do
    cond do
      disarmed_held?(data, st) and (data.separation == nil or (data.separation.want == :go and data.separation.phase == :resumed)) ->
        # Let go, its AUTO came while (or after) the autopilot disarmed it.
        restart(data, :disarmed_while_held)

      disarmed_held?(data, st) ->
        {:keep_state, data, cancel_watches()}

      disarmed_after_arming?(data, st) ->
        disarmed_before_take_off(data, st)

      true ->
        judge_flight(data, st)
    end
  end

  # Seen armed in this flight, then disarmed before it began (see disarmed_before_flight?/2).
  defp disarmed_after_arming?(data, st), do: data.flight.armed_seen and disarmed_before_flight?(data, st)

  # Seen armed, disarmed before it left the ground: judged by the rearm
  # watch (watch_disarmed/2), not as the end of its flight, nor as a landing
  # whose reports are awaited (their timer is this state's only one here).
  defp disarmed_before_take_off(data, st) do
    {data, disarmed} = watch_disarmed(%{data | flight: %{data.flight | landing_check: false}}, st)
    {:keep_state, data, [{:state_timeout, :cancel} | disarmed]}
  end

  defp judge_flight(data, st) do
    {verdict, progress, flight} = Flight.judge(data.flight, st)
    verdict = separated_verdict(data, st, verdict)
    data = back_in_mission(data, st)
    {data, grounded} = watch_grounded(%{data | flight: flight}, st)
    {data, still} = watch_still(data, st)
    {data, disarmed} = watch_disarmed(data, st)
    watch = grounded ++ still ++ disarmed
    if progress, do: Platform.progress(data.owner, progress)

    case verdict do
      :flying ->
        {:keep_state, data, watch}

      :done ->
        done(data)

      # Left to what took it (a failsafe's RTL or LAND, the pilot): never
      # overridden; failed once the vehicle has had the time to say why (its
      # STATUSTEXT may come just after the HEARTBEAT with the new mode).
      {:left, cause} ->
        {:keep_state, %{data | leaving: cause}, [{:state_timeout, Clock.to_real_ms(@reason_ms), :said} | watch]}

      # A landing mission's disarm comes before its last report (ArduPilot
      # reports the final item after "Disarming motors"): the reports are
      # given their time, which a state change would not cut short.
      :check_landed ->
        {:keep_state, data, [{:state_timeout, max(Clock.to_real_ms(@landing_reports_ms), @landing_reports_floor_real_ms), :check_landed} | watch]}
    end
  end

  # Armed on the ground (where a take-off that does not climb leaves it): a
  # timer from the first time it is seen so, cancelled once it is not. (A
  # rover, boat or submarine is never in the air: nothing to watch.)
  defp watch_grounded(data, st) do
    cond do
      not Airframe.takes_off?(data.airframe) ->
        {data, []}

      not on_ground_armed?(st) and data.grounded != nil ->
        {%{data | grounded: nil}, [{{:timeout, :grounded}, :cancel}]}

      on_ground_armed?(st) and data.grounded == nil ->
        {%{data | grounded: %{at: st.position}}, [{{:timeout, :grounded}, max(Clock.to_real_ms(@grounded_timeout_ms), @grounded_floor_real_ms), :grounded}]}

      true ->
        {data, []}
    end
  end

  # Disarmed on the ground before the flight began (see @rearm_grace_ms): a
  # timer from the first time it is seen so, cancelled once it is not.
  defp watch_disarmed(data, st) do
    idle = disarmed_before_flight?(data, st)

    cond do
      idle and not data.disarmed_idle ->
        {%{data | disarmed_idle: true}, [{{:timeout, :disarmed}, max(Clock.to_real_ms(@rearm_grace_ms), @rearm_grace_floor_real_ms), :disarmed}]}

      not idle and data.disarmed_idle ->
        {%{data | disarmed_idle: false}, [{{:timeout, :disarmed}, :cancel}]}

      true ->
        {data, []}
    end
  end

  # Disarmed (on the ground, for one that takes off) before the flight
  # began: never seen armed in this flight — a rover, boat or submarine too:
  # ArduRover SITL on a loaded host once armed and disarmed in one instant,
  # and the mission would have waited in AUTO, disarmed, for ever —, or a
  # copter seen armed that never left the ground, its take-off still ahead,
  # in AUTO or GUIDED. Over 30 % loss on a loaded host, ArduCopter's
  # DISARM_DELAY ran out in GUIDED before MISSION_START came; the heartbeat
  # saying so was lost, and MISSION_CURRENT's ACTIVE (the start taken while
  # disarmed) came with the armed bit of the heartbeat before it: seen
  # armed, then disarmed in AUTO at the take-off.
  defp disarmed_before_flight?(data, st),
    do: disarmed_on_ground?(st) and (not data.flight.armed_seen or (st.mode in [:auto, :guided] and take_off_ahead?(data, st)))

  defp take_off_ahead?(data, st) do
    take_off = Enum.find(data.items, &(&1.command == @takeoff))
    current = st.mission.current
    Airframe.takes_off?(data.airframe) and not data.flight.airborne_seen and take_off != nil and (current == nil or current <= take_off.seq)
  end

  # A copter disarmed during its take-off's spool-up may be reported
  # landed TAKEOFF until its next EXTENDED_SYS_STATE: below a metre, it
  # stands on the ground.
  defp disarmed_on_ground?(st), do: not st.armed? and (st.landed in [:on_ground, nil] or (st.landed == :takeoff and low?(st)))

  defp low?(%{relative_altitude: h}), do: not is_number(h) or h < @ground_m

  defp disarmed_before_start(data) do
    if Airframe.takes_off?(data.airframe),
      do: {:disarmed_before_take_off, data.rearms + 1},
      else: {:disarmed_before_start, data.rearms + 1}
  end

  # Standing still in AUTO short of the waypoint it flies to (not at a
  # loiter or a delay, where standing is the mission, nor held apart from
  # another vehicle): a timer from the first time it is seen so, where it
  # stood and at which item, cancelled once it moves or goes on.
  defp watch_still(data, st) do
    standing = standing_short(data, st)

    cond do
      standing == nil and data.still != nil -> {%{data | still: nil}, [{{:timeout, :stuck}, :cancel}]}
      standing == nil -> {data, []}
      data.still != nil and data.still.seq == standing.seq and near?(data.still.at, standing.at, @still_m) -> {data, []}
      true -> {%{data | still: standing}, [{{:timeout, :stuck}, Clock.to_real_ms(@stuck_timeout_ms), :stuck}]}
    end
  end

  # %{at, seq, short} when the vehicle stands in AUTO, armed, bound for a waypoint farther than @short_m; else nil.
  defp standing_short(%{separation: nil, items: items}, %{armed?: true, mode: :auto, position: %{} = p, mission: %{current: seq, state: :active}} = st)
       when is_integer(seq) do
    item = Enum.at(items, seq)

    with %{command: @waypoint, x: x, y: y} when x != 0 <- item,
         true <- Dolphin.Vehicles.View.speed(st) < 0.2,
         short when short > @short_m <- Dolphin.Geo.distance(Dolphin.Geo.location(p.lat, p.lon), Dolphin.Geo.location(x / 1.0e7, y / 1.0e7)) do
      %{at: p, seq: seq, short: short}
    else
      _ -> nil
    end
  end

  defp standing_short(_data, _st), do: nil

  defp near?(a, b, metres), do: Dolphin.Geo.distance(Dolphin.Geo.location(a.lat, a.lon), Dolphin.Geo.location(b.lat, b.lon)) <= metres

  # Still where it stood, at the same item: stuck, with where.
  defp stuck(%{still: %{} = still} = data, st) do
    case standing_short(data, st) do
      %{seq: seq, at: at, short: short} when seq == still.seq ->
        if near?(still.at, at, @still_m),
          do: {:stuck, {:stuck, div(@stuck_timeout_ms, 1000), {seq, length(data.items) - 1, Mission.item_name(Enum.at(data.items, seq)), round(short)}}},
          else: :moving

      _ ->
        :moving
    end
  end

  defp stuck(_data, _st), do: :moving

  defp on_ground_armed?(%{armed?: true, landed: :on_ground}), do: true
  defp on_ground_armed?(%{armed?: true, landed: landed, relative_altitude: alt}) when landed in [nil, :takeoff] and is_number(alt), do: alt < @ground_m
  defp on_ground_armed?(_st), do: false

  # Still armed on the ground, and where it was then (one moving, low over
  # ground lower than home, is flying).
  defp still_grounded?(%{grounded: %{at: at}}, st) do
    on_ground_armed?(st) and (at == nil or st.position == nil or near?(at, st.position, @here_m))
  end

  defp still_grounded?(_data, _st), do: false

  defp grounded(data, st) do
    current = st.mission.current
    item = if is_integer(current), do: Enum.at(data.items, current)
    at = if item, do: {current, length(data.items) - 1, Mission.item_name(item), item.command == @takeoff}
    {:grounded, div(@grounded_timeout_ms, 1000), at}
  end

  # What the vehicle said since the mission started.
  # (A call to the vehicle's process, once, as the mission fails: the views carry no texts.)
  defp texts(data), do: Dolphin.Vehicles.State.texts_since(data.flight_texts, Vehicles.status_texts(data.vehicle))

  # --- the end ----------------------------------------------------------------

  defp cancel_task(%{task: nil}), do: :ok
  defp cancel_task(%{task: task}), do: Task.shutdown(task, :brutal_kill) && :ok

  defp done(data) do
    Platform.done(data.owner)
    {:stop, :normal, data}
  end

  defp fail(state, data, cause, opts \\ []) do
    failure = %Dolphin.Mission.Failure{
      mission: data.name,
      vehicle: data.vehicle,
      step: state,
      cause: cause,
      status_texts: Keyword.get(opts, :texts, []),
      vehicle_fault?: Keyword.get(opts, :vehicle_fault?, false)
    }

    Platform.failed(data.owner, failure)
    # A failed mission leaves the vehicle holding, not flying on.
    _ = if Keyword.get(opts, :hold, true) and commanded?(state), do: hold(data.vehicle, true)
    {:stop, :normal, data}
  end
end
