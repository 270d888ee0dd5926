defmodule Dolphin.Vehicles.Manoeuvres do
  @moduledoc """
  ArduPilot's manoeuvres, as a ground station has to ask for them: hold
  position, arm when the autopilot is ready, take off, land, go to a point.
  The mission executor (`Dolphin.Mission.Platform`) and the console
  (`Dolphin.Console`) both fly vehicles through this module, so what
  ArduCopter needs is written once:

    * **hold** — as the vehicle's airframe holds (`hold_modes/1`): a copter
      BRAKE, else GUIDED (never LOITER, which is flown by a pilot's sticks and
      sinks without RC throttle); a plane circles in LOITER; a rover or boat
      LOITER (HOLD only cuts the throttle); a submarine POSHOLD. A vehicle
      still on the ground is disarmed instead; one its autopilot is bringing
      down (RTL, LAND, a submarine's SURFACE: a failsafe or the pilot
      decided) is left alone.
    * **arm when ready** — ArduCopter refuses to arm for about a minute after
      boot ("PreArm: Need Position Estimate"): the arm command is sent again
      every second of clock time while the refusal may pass, for a bounded
      time. It does not arm in AUTO: GUIDED first (which ArduSub and
      ArduPlane also refuse until they have a position: asked again the same
      way, `guided/2`).
    * **take off** — GUIDED, arm when ready, NAV_TAKEOFF (altitude above home).
    * **land**, **go to** — NAV_LAND; DO_REPOSITION in GUIDED.

  Every manoeuvre returns `:ok` or `{:error, %Dolphin.ManoeuvreError{}}`, which
  carries the vehicle's refusal and what its autopilot said meanwhile. They
  block their caller (a console, or a worker of the executor) until the
  vehicle has answered; waits are in `Dolphin.Clock` time.

      :ok = Dolphin.Vehicles.Manoeuvres.take_off(1, 20)
      :ok = Dolphin.Vehicles.Manoeuvres.go_to(1, {40.4444, -7.3754, 15})
      :ok = Dolphin.Vehicles.Manoeuvres.hold(1)
  """

  alias Dolphin.{Clock, CommandError, ManoeuvreError, Vehicles}
  alias Dolphin.Vehicles.State

  # Modes in which the autopilot itself brings the vehicle down (or a
  # submarine up).
  @landing_modes [:rtl, :land, :smart_rtl, :auto_rtl, :qland, :qrtl, :surface]
  # Refusals of an arm command that pass once the autopilot is ready (pre-arm
  # checks fail as FAILED or DENIED; a busy or silent autopilot as the others).
  @not_ready [:failed, :temporarily_rejected, :denied, :timeout]
  @arm_retry_ms 1_000
  @arm_within_ms 30_000

  @typedoc """
  What a manoeuvre tells its `:report` function as it goes: a step accepted
  (`:guided`, `:arm`, `:take_off`), or an arm refusal it will try again
  (`{:refused, :arm, refusal, texts, left_ms}`: the autopilot's texts about
  it, the clock time left to try), given when the refusal differs from the
  one before.
  """
  @type report :: {:accepted, :guided | :arm | :take_off} | {:refused, :arm, CommandError.t(), [{integer(), String.t()}], integer()}

  @type result :: :ok | {:error, ManoeuvreError.t()}

  @doc """
  Whether a vehicle's view (`Dolphin.Vehicles.View`) says it is in the air:
  armed, and its EXTENDED_SYS_STATE says flying (taking off, in the air,
  landing) or, without one, it is more than a metre above home.
  """
  @spec in_air?(Dolphin.Vehicles.View.t()) :: boolean()
  def in_air?(view) do
    view.armed? and
      (view.landed in [:in_air, :takeoff, :landing] or (view.landed == nil and (view.relative_altitude || 0) > 1))
  end

  @doc """
  Makes a vehicle safe: holding position in the air (BRAKE, else GUIDED),
  disarmed on the ground, left alone when its autopilot is bringing it down
  or when it is not known. `fresh: true`: the state may be older than
  commands just accepted (arming, MISSION_START), so the vehicle is held as
  if flying whatever its telemetry says.
  """
  @spec hold(byte(), keyword()) :: result()
  def hold(vehicle, opts \\ []) do
    fresh? = Keyword.get(opts, :fresh, false)

    case Vehicles.view(vehicle) do
      {:error, :unknown_vehicle} -> :ok
      {:ok, %{mode: mode}} when mode in @landing_modes -> :ok
      {:ok, %{armed?: false}} when not fresh? -> :ok
      {:ok, %{airframe: airframe} = view} when not fresh? -> hold_as_is(vehicle, airframe, view)
      {:ok, %{airframe: airframe}} -> brake(vehicle, airframe)
    end
  end

  # Holding already, or on the ground (disarmed there), from the view just read.
  defp hold_as_is(vehicle, airframe, view) do
    cond do
      view.mode in hold_modes(airframe) -> :ok
      view.landed == :on_ground -> disarm_or_brake(vehicle, airframe)
      true -> brake(vehicle, airframe)
    end
  end

  @doc """
  The modes that hold a vehicle of `airframe` where it is, the first the one
  a stop asks for: a copter brakes (BRAKE), a plane circles the point
  (LOITER: it cannot stand still), a rover or boat holds position (LOITER:
  HOLD only cuts the throttle, and a boat drifts in it), a submarine holds
  position and depth (POSHOLD); GUIDED (HOLD for a rover or boat) when the
  first is refused.

      iex> Dolphin.Vehicles.Manoeuvres.hold_modes(:plane)
      [:loiter, :guided]
  """
  @spec hold_modes(atom() | nil) :: [atom()]
  def hold_modes(airframe), do: Dolphin.Airframe.of(airframe).hold_modes()

  # An accepted DO_SET_MODE means the mode has changed (ArduPilot acks after
  # the switch); the heartbeat shows it within a second.
  defp brake(vehicle, airframe) do
    Enum.reduce_while(hold_modes(airframe), nil, fn mode, _ ->
      case command(vehicle, mode |> Atom.to_string() |> String.upcase(), fn -> Vehicles.set_mode(vehicle, mode) end) do
        :ok -> {:halt, :ok}
        {:error, e} -> {:cont, {:error, %ManoeuvreError{manoeuvre: :hold, vehicle: vehicle, action: "holding position", refusal: e, texts: e.texts}}}
      end
    end)
  end

  # "On the ground" may be a second old: a vehicle that refuses the disarm is flying.
  defp disarm_or_brake(vehicle, airframe) do
    case command(vehicle, "disarming on the ground", fn -> Vehicles.disarm(vehicle) end) do
      :ok -> :ok
      {:error, _} -> brake(vehicle, airframe)
    end
  end

  @doc """
  Arms the motors, sending the command again every second of clock time
  while the autopilot refuses it in a way that passes once it is ready, for
  at most `within:` ms of clock time (default 30 000; 0: once). A vehicle
  armed already is left as it is. `report:` a function given `t:report/0`s.
  """
  @spec arm_when_ready(byte(), keyword()) :: result()
  def arm_when_ready(vehicle, opts \\ []) do
    within = Keyword.get(opts, :within, @arm_within_ms)
    report = Keyword.get(opts, :report, fn _ -> :ok end)
    texts = Vehicles.status_texts(vehicle)
    arm(vehicle, %{deadline: Clock.now_ms() + within, within: within, texts: texts, report: report, said: nil})
  end

  defp arm(vehicle, a) do
    case Vehicles.view(vehicle) do
      {:ok, %{armed?: true}} ->
        :ok

      _ ->
        before = Vehicles.status_texts(vehicle)

        case Vehicles.arm(vehicle) do
          {:ok, :accepted} ->
            a.report.({:accepted, :arm})
            :ok

          {:error, %CommandError{result: result} = e} when result in @not_ready ->
            now = Vehicles.status_texts(vehicle)
            left = a.deadline - Clock.now_ms()

            if left <= 0 do
              {:error, %ManoeuvreError{manoeuvre: :arm, vehicle: vehicle, action: "arming", refusal: e, waited_ms: a.within, texts: State.texts_since(a.texts, now)}}
            else
              news = State.texts_since(before, now)
              said = {Exception.message(e), news}
              if said != a.said, do: a.report.({:refused, :arm, e, news, left})
              Clock.sleep(@arm_retry_ms)
              arm(vehicle, %{a | said: said})
            end

          {:error, e} ->
            {:error, %ManoeuvreError{manoeuvre: :arm, vehicle: vehicle, action: "arming", refusal: e, texts: State.texts_since(a.texts, Vehicles.status_texts(vehicle))}}
        end
    end
  end

  @doc """
  Switches to GUIDED, unless the vehicle is in GUIDED already (then nothing
  is sent); a refusal that passes once the autopilot has a position is
  asked again for `within:` ms of clock time (default 0: once). `report:`
  as for `arm_when_ready/2`. `force: true` sends it whatever the view says:
  for a caller that has just had another mode accepted, which the view may
  not show yet.
  """
  @spec guided(byte(), keyword()) :: result()
  def guided(vehicle, opts \\ []) do
    within = Keyword.get(opts, :within, 0)
    deadline = Clock.now_ms() + within

    force = Keyword.get(opts, :force, false)

    case Vehicles.view(vehicle) do
      {:ok, %{mode: :guided}} when not force -> :ok
      _ -> guided_until(vehicle, deadline) |> reported(:guided, opts)
    end
  end

  # ArduSub (and ArduPlane) refuse GUIDED until their EKF has a position
  # ("Mode change failed: GUIDED requires position"): asked again every
  # second of clock time while such a refusal may pass, until the deadline.
  defp guided_until(vehicle, deadline) do
    case command(vehicle, "switching to GUIDED", fn -> Vehicles.set_mode(vehicle, :guided) end) do
      {:error, %ManoeuvreError{refusal: %CommandError{result: result}}} = error when result in @not_ready ->
        if Clock.now_ms() >= deadline,
          do: error,
          else:
            (
              Clock.sleep(@arm_retry_ms)
              guided_until(vehicle, deadline)
            )

      other ->
        other
    end
  end

  @doc """
  Takes off to `altitude` metres above home: GUIDED, arm when ready (unless
  armed; `within:` as for `arm_when_ready/2`), then NAV_TAKEOFF. `report:`
  as for `arm_when_ready/2`.
  """
  @spec take_off(byte(), number(), keyword()) :: result()
  def take_off(vehicle, altitude, opts \\ []) do
    armed? = match?({:ok, %{armed?: true}}, Vehicles.view(vehicle))

    with :ok <- guided(vehicle, opts),
         :ok <- if(armed?, do: :ok, else: arm_when_ready(vehicle, opts)) do
      command(vehicle, "take-off", fn -> Vehicles.takeoff(vehicle, altitude) end) |> reported(:take_off, opts)
    end
  end

  @doc "Lands where the vehicle is (ArduCopter disarms on the ground)."
  @spec land(byte()) :: result()
  def land(vehicle), do: command(vehicle, "land", fn -> Vehicles.land(vehicle) end)

  @doc """
  Flies to a point and holds there, switching to GUIDED: `{lat, lon, alt}`
  in degrees and metres above home (`amsl: true`: above mean sea level).
  """
  @spec go_to(byte(), {number(), number(), number()}, keyword()) :: result()
  def go_to(vehicle, point, opts \\ []) do
    frame = if opts[:amsl], do: 0, else: 6
    # p1 -1: default speed; p2 bit 0: switch to GUIDED; p4 NaN: keep the yaw behaviour.
    command(vehicle, "go to", fn -> Vehicles.command_int(vehicle, :mav_cmd_do_reposition, [-1, 1, 0, :nan], point, frame: frame) end)
  end

  @doc """
  Sends one command (`send` calls `Dolphin.Vehicles`) and, if the vehicle
  refuses it, says so with what the autopilot said meanwhile; `action`
  names it in the error.
  """
  @spec command(byte(), String.t(), (() -> {:ok, term()} | {:error, CommandError.t()})) :: result()
  def command(vehicle, action, send) do
    before = Vehicles.status_texts(vehicle)

    case send.() do
      {:ok, _} -> :ok
      {:error, e} -> {:error, %ManoeuvreError{manoeuvre: :command, vehicle: vehicle, action: action, refusal: e, texts: State.texts_since(before, Vehicles.status_texts(vehicle))}}
    end
  end

  defp reported(:ok, step, opts) do
    if report = opts[:report], do: report.({:accepted, step})
    :ok
  end

  defp reported(error, _step, _opts), do: error
end
