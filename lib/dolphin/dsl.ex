defmodule Dolphin.DSL do
  @moduledoc """
  The vocabulary of scripts (docs/language.md is the reference), imported by
  `use Dolphin.Script` together with `Dolphin.DSL.Values` (locations, areas,
  units) and the `mission` block of `Dolphin.DSL.Mission`.

  Every word is sugar: functions delegate to `Dolphin.Engine` (tasks),
  `Dolphin.Fleet` (vehicles) and `Dolphin.Script.Statements` (statements); the macros
  only turn expressions into closures (conditions, `action` bodies, loop
  bodies) and record the script line.

  | word | plain function |
  | --- | --- |
  | `pick(opts)`, `release(set)` | `Dolphin.Script.Statements.pick/1`, `Dolphin.Script.Statements.release/1` |
  | `union/2`, `difference/2`, `intersection/2`, `filter/2` | `Dolphin.Fleet.VehicleSet` |
  | `battery(v)`, `position(v)`, `altitude(v)`, `relative_altitude(v)`, `mode(v)`, `armed?(v)`, `connected?(v)`, `mission_progress(v)` | `Dolphin.Engine.Snapshot` (written in a condition), `Dolphin.Engine.Watcher.vehicle/2` (elsewhere) |
  | `set_connection_timeout(t)`, `set_connection_timeout(set, t)` | `Dolphin.Script.Statements.set_connection_timeout/1,2` |
  | `idle(d)`, `on(t, set)`, `during(d, t)`, `watch(t, on_error: h)`, `reassign(t)`, `reassign(t, from: set)`, `named(t, name)`, `t1 >>> t2`, `t1 \\|\\|\\| t2` | `Dolphin.Engine` |
  | `action do ... end`, `condition(c)`, `until(t, c)`, `wait_for(c)`, `wait_for(c, then: t)`, `one_of do c -> t ... end`, `all_of do ... end` | `Dolphin.Engine` with a `Dolphin.Engine.Cond` |
  | `execute(t)`, `execute(%{v1 => t1, _: t2})`, `execute action do ... end` | `Dolphin.Script.Statements.execute/1` |
  | `forever do ... end`, `forever(state, fn s -> ... end)`, `repeat(n) do ... end` | `Dolphin.Script.Statements.forever/1,2`, `Dolphin.Script.Statements.repeat/2` |
  | `message`, `post`, `consume`, `poll`, `pause`, `halt`, `ask`, `send_message`, `param`, `set_param` | `Dolphin.Script.Statements` |

  Conditions are ordinary expressions — `battery(v1) < 0.3`, `poll(:go)`,
  `connected?(v) and mode(v) == :guided` — re-evaluated whenever what they
  read changes: the macros rewrite the readers written in the expression
  (`battery/1`, ..., `poll/1,2`) into those of `Dolphin.Engine.Snapshot`, and
  the condition becomes a function of its snapshot (`Dolphin.Engine.Cond`). A
  reader called inside a function of the script's own reads live; a
  condition calling one is also re-evaluated on the changes of the vehicles
  its task flies (docs/language.md, "Conditions").

  ## Unknown values

  What a vehicle has not reported yet reads as `nil`: `battery/1`,
  `position/1`, `altitude/1`, `relative_altitude/1`, `mode/1` and
  `mission_progress/1` until the first report, `distance/2`, `near?/3` and
  `contains?/2` of an unknown position, arithmetic on an unknown value. A
  condition that depends on an unknown value is **not met**, and reading one
  never raises:

    * a comparison (`<`, `<=`, `>`, `>=`, `==`, `!=`, `===`, `!==`, `in`)
      with an unknown side is unknown — `battery(v) >= 0.9` does not hold before
      the battery is reported (Elixir alone would say `nil >= 0.9` is true);
    * `not`/`!` of unknown is unknown: `not (battery(v) < 0.3)` does not hold
      either;
    * `and`/`&&`, `or`/`||` follow three-valued logic: `false and unknown`
      is false, `true or unknown` is true, anything else with an unknown
      side is unknown; `connected?(v) == false or battery(v) < 0.2` holds as
      soon as the vehicle is lost, whatever its battery;
    * any other expression is unknown when its value is `nil`;
    * a condition holds only when its value is true; unknown is treated as
      false, so `wait_for`, `until`, `one_of` and `all_of` keep waiting.

  `x == nil` and `x != nil` (a literal `nil`) ask whether a value is known:
  `wait_for(position(v) != nil)` waits for the first position. The same
  rules apply to the function given to `filter/2` when it is written in
  place (`filter(vs, fn v -> battery(v) > 0.5 end)` leaves out the
  vehicles whose battery is unknown). Functions the condition calls are
  evaluated as Elixir: the rules apply to the condition's own expression.

  `>>>` binds tighter than `|||`, as `>>` and `|` do in Dolphin:
  `a >>> b ||| c` is `(a >>> b) ||| c`.
  """

  import Dolphin.DSL.Expand

  alias Dolphin.Engine
  alias Dolphin.Engine.Snapshot
  alias Dolphin.Fleet.VehicleSet
  alias Dolphin.Script.Statements

  # --- vehicles ---

  @doc """
  Picks vehicles for the script and returns them as a vehicle set: blocks
  until `count` *available* vehicles (connected, picked by nobody, not busy)
  match every filter. Options: `count:` (default 1), `type:` (`:uav`,
  `:ugv`, `:usv`, `:uuv`, `:other` or a list), `airframe:` (`:copter`,
  `:plane`, `:quadplane`, `:rover`, `:boat`, `:sub` or a list), `payload:`
  (an atom or a list, all required), `sensors:` (declared sensors, named
  in place: `[:smoke]`; a vehicle on which each has been heard), `region:` (an `area/2`), `id:` (a system id or a list),
  `timeout:` (clock ms, default `:infinity`).

      v = pick(type: :uav, timeout: seconds(30))
      pair = pick(count: 2, payload: :camera, region: area(base, km(2)))
      subs = pick(count: 3, type: :uuv, airframe: :sub, payload: :sidescan)

  A timeout stops the script with a `Dolphin.Fleet.PickError` naming the
  requirement and the known vehicles (`pick timed out after 30000 ms: wanted
  1 vehicle, type :uav; ...`), reported at the line of the `pick`; a bad
  option raises `ArgumentError`. See docs/language.md, "Vehicles".
  """
  defmacro pick(opts \\ []), do: at_line(quote(do: Dolphin.Script.Statements.pick(unquote(Dolphin.DSL.Sensors.pick_opts(opts, __CALLER__)))), __CALLER__)

  @doc """
  Makes vehicles the script picked available again: a set or a list of sets.
  Returns `:ok`. A script's vehicles are released when it ends anyway.

      release(v)
      release([scout, spare])
  """
  defdelegate release(sets), to: Statements

  @doc """
  The vehicles of either set.

      everyone = union(scouts, spares)
  """
  defdelegate union(a, b), to: VehicleSet

  @doc """
  The vehicles of `a` that are not in `b`.

      others = difference(all, v)
  """
  defdelegate difference(a, b), to: VehicleSet

  @doc """
  The vehicles in both sets.

      both = intersection(cameras, in_zone)
  """
  defdelegate intersection(a, b), to: VehicleSet

  @doc """
  The vehicles of `set` for which `fun`, given a one-vehicle set, is truthy.
  A `fn` written in place is a condition (see "Unknown values"): a vehicle
  whose value is unknown is left out.

      charged = filter(all, fn v -> battery(v) > 0.9 end)
  """
  defmacro filter(set, {:fn, meta, [{:->, arrow_meta, [args, body]}]}),
    do: quote(do: VehicleSet.filter(unquote(set), unquote({:fn, meta, [{:->, arrow_meta, [args, quote(do: Dolphin.Engine.Cond.met?(unquote(logic(body))))]}]})))

  defmacro filter(set, fun), do: quote(do: VehicleSet.filter(unquote(set), unquote(fun)))

  @doc """
  A vehicle not heard for longer than `ms` (clock ms; default 20 s) is lost:
  the task running on it fails. For the vehicles the script picked and will
  pick; returns `:ok`, raises `ArgumentError` unless `ms` is positive.

      set_connection_timeout(minutes(10))
  """
  defdelegate set_connection_timeout(ms), to: Statements

  @doc """
  The connection timeout (clock ms) of the vehicles of `set`.

      set_connection_timeout(v, seconds(30))
  """
  defdelegate set_connection_timeout(set, ms), to: Statements

  @typedoc "A one-vehicle set (or a system id)."
  @type vehicle :: VehicleSet.t() | non_neg_integer()

  # The readers share one paragraph: what they return before the first report
  # and how conditions treat that.
  @unknown """
  `nil` until the vehicle has reported it. In a condition, an unknown value
  makes the condition not met (it never raises): `wait_for(battery(v) >= 0.9)`
  waits until the battery is known and at least 90 %. Raises `ArgumentError`
  for a set of several vehicles.
  """

  @doc """
  The remaining battery of a one-vehicle set (or a system id), `0.0..1.0`;
  #{@unknown}
      until(survey, battery(v) < 0.3) >>> return_home
      message("battery at \#{round(battery(v) * 100)} %")
  """
  @spec battery(vehicle()) :: float() | nil
  def battery(v), do: Snapshot.battery(nil, v)

  @doc """
  The position of a vehicle: a `Dolphin.Geo.Location` (latitude, longitude,
  height `h` above mean sea level); #{@unknown}
      until(patrol, not contains?(zone, position(v)))
      home_pos = position(v)
  """
  @spec position(vehicle()) :: Dolphin.Geo.Location.t() | nil
  def position(v), do: Snapshot.position(nil, v)

  @doc """
  The height of a vehicle above mean sea level, in metres (what missions
  use); #{@unknown}
      wait_for(altitude(v) > 1000, then: photos)
  """
  @spec altitude(vehicle()) :: float() | nil
  def altitude(v), do: Snapshot.altitude(nil, v)

  @doc """
  The height of a vehicle above its home, in metres; #{@unknown}
      wait_for(relative_altitude(v) > 30, then: survey)
  """
  @spec relative_altitude(vehicle()) :: float() | nil
  def relative_altitude(v), do: Snapshot.relative_altitude(nil, v)

  @doc """
  The flight mode of a vehicle: `:stabilize`, `:guided`, `:auto`, `:brake`,
  `:land`, `:rtl`, ...; #{@unknown}
      until(watch_only, mode(v) == :rtl)
  """
  @spec mode(vehicle()) :: atom() | nil
  def mode(v), do: Snapshot.mode(nil, v)

  @doc """
  Whether a vehicle is armed (`false` until it has reported otherwise).

      wait_for(not armed?(v), then: swap_battery)
  """
  @spec armed?(vehicle()) :: boolean()
  def armed?(v), do: Snapshot.armed?(nil, v)

  @doc """
  Whether a vehicle is heard: `false` once it is silent for longer than its
  connection timeout (see `set_connection_timeout/1`).

      one_of do
        not connected?(v) -> action do message("lost \#{inspect(v)}") end
        battery(v) < 0.2 -> return_home
      end
  """
  @spec connected?(vehicle()) :: boolean()
  def connected?(v), do: Snapshot.connected?(nil, v)

  @doc """
  `{reached, total}`: the last mission item reached (0 before the first) and
  the items of the mission, counted from its last upload; #{@unknown}
  Tuples compare element by element: `mission_progress(v) >= {3, 0}` holds
  once item 3 is reached.

      until(survey, mission_progress(v) >= {5, 0})
  """
  @spec mission_progress(vehicle()) :: {non_neg_integer(), non_neg_integer()} | nil
  def mission_progress(v), do: Snapshot.mission_progress(nil, v)

  # --- tasks ---

  @doc """
  A task that does nothing for `d` ms of clock time, then is done; raises
  `ArgumentError` unless `d` is a non-negative number.

      execute idle(seconds(30)) >>> survey
  """
  defdelegate idle(d), to: Engine

  @doc """
  `t`, whose platform tasks (missions) may only use the vehicles of `set`.

      execute on(survey >>> return_home, v)
      execute survey |> on(v)
  """
  defdelegate on(t, set), to: Engine

  @doc """
  `t` for at most `d` ms of clock time: then `t` is stopped (its vehicles
  hold) and `during` is done; done earlier if `t` is; fails if `t` fails.

      execute during(minutes(10), patrol) >>> return_home
  """
  defdelegate during(d, t), to: Engine

  @doc """
  `t` with an error handler. When `t` fails: `on_error: :ignore` — done;
  `:propagate` (the default) — fails the same way; `fn failure -> ... end` —
  runs with the `Dolphin.Engine.Failure`; if it returns a task, that task
  runs and `watch` ends as it does, else `watch` is done.

      execute watch(survey, on_error: fn failure ->
        message("survey failed: " <> Dolphin.Engine.Failure.message(failure))
        return_home
      end)
  """
  defdelegate watch(t, opts), to: Engine

  @doc """
  `t` whose missions are taken over by another vehicle when theirs is lost
  or fails them (a battery failsafe, a refused arm): the mission is resumed
  by the first free vehicle of `from:` (default: the vehicles the script
  picked) that meets its requirements, from the first item not reached — a
  take-off where it stands, then the rest; a survey goes on with the passes
  not flown. Same as `watch(t, on_error: :reassign, from: set)`; see
  `Dolphin.Engine.Watch`.

      team = pick(count: 3, type: :uav)
      execute reassign(survey_north, from: team) ||| reassign(survey_south, from: team)
  """
  defdelegate reassign(t, opts \\ []), to: Engine

  @doc """
  `t` with a name, shown in events, errors and the console.

      execute named(survey ||| photos, "morning round")
  """
  defdelegate named(t, name), to: Engine

  @doc """
  Sequence: `t1`, then `t2` once `t1` is done; a failure ends it (`t2` does
  not run). Binds tighter than `|||`, as tight as `|>`:

      execute until(survey, battery(v) < 0.3) >>> return_home
      execute takeoff >>> survey ||| photos      # (takeoff >>> survey) ||| photos
  """
  @spec term() >>> term() :: Dolphin.Engine.Sequence.t()
  def t1 >>> t2, do: Engine.sequence([t1, t2])

  @doc """
  Concurrency: `t1` and `t2` at the same time, on distinct vehicles; done
  when both are. When one fails the other is stopped and the whole fails.

      execute on(survey_north, v1) ||| on(survey_south, v2)
  """
  @spec term() ||| term() :: Dolphin.Engine.Concurrent.t()
  def t1 ||| t2, do: Engine.concurrent([t1, t2])

  @doc """
  A task that runs the block once, in its own process: done when it
  returns, failed if it raises, throws or exits.

      execute idle(seconds(20)) >>> action do post(:go, true) end
  """
  defmacro action(do: block), do: action_ast(nil, block, __CALLER__)

  @doc """
  A named `action/1`.

      execute action "report" do message("battery \#{battery(v)}") end
  """
  defmacro action(name, do: block), do: action_ast(name, block, __CALLER__)

  @doc """
  A task that is done when the condition `c` holds (at once if it already
  does). `c` is an expression, re-evaluated when what it reads changes.

      execute condition(battery(v) >= 0.9) >>> survey
  """
  defmacro condition(c), do: quote(do: Dolphin.Engine.condition(unquote(cond_ast(c, __CALLER__)), meta: unquote(meta(__CALLER__))))

  @doc """
  `t` until the condition `c` holds: then `t` is stopped (its vehicles hold)
  and `until` is done; done earlier if `t` is; if `c` holds at the start `t`
  does not run. Fails if `t` fails.

      execute until(survey, battery(v) < 0.3) >>> return_home
  """
  defmacro until(t, c), do: quote(do: Dolphin.Engine.until(unquote(t), unquote(cond_ast(c, __CALLER__)), meta: unquote(meta(__CALLER__))))

  @doc """
  A task that waits until the condition `c` holds, then is done.

      execute wait_for(poll(:target_found))
  """
  defmacro wait_for(c), do: quote(do: Dolphin.Engine.wait_for(unquote(cond_ast(c, __CALLER__)), nil, meta: unquote(meta(__CALLER__))))

  @doc """
  `wait_for(c, then: t)`: waits until `c` holds, then runs `t` and ends as it
  does. Anything but `then: task` raises `ArgumentError` at compile time.

      execute %{v => wait_for(battery(v) >= 0.9, then: until(survey, battery(v) < 0.3) >>> return_home)}
  """
  defmacro wait_for(c, opts) do
    case opts do
      [then: t] -> quote(do: Dolphin.Engine.wait_for(unquote(cond_ast(c, __CALLER__)), unquote(t), meta: unquote(meta(__CALLER__))))
      _ -> raise ArgumentError, "wait_for/2 takes `then: task`, got: #{Macro.to_string(opts)}"
    end
  end

  @doc """
  Runs the task of the first branch whose condition holds (checked in order
  at the start, so the earliest wins a tie); the others never start.

      execute one_of do
        battery(v) < 0.3 -> return_home
        poll(:target_found) -> circle_target
      end
  """
  defmacro one_of(do: clauses), do: quote(do: Dolphin.Engine.one_of(unquote(branches(clauses, :one_of, __CALLER__)), meta: unquote(meta(__CALLER__))))

  @doc """
  Runs every branch's task as soon as its own condition holds; done when all
  are. A failure stops the running tasks, drops the waiting branches and
  fails `all_of`.

      execute all_of do
        battery(v1) >= 0.9 -> survey_north |> on(v1)
        battery(v2) >= 0.9 -> survey_south |> on(v2)
      end
  """
  defmacro all_of(do: clauses), do: quote(do: Dolphin.Engine.all_of(unquote(branches(clauses, :all_of, __CALLER__)), meta: unquote(meta(__CALLER__))))

  # --- running ---

  @doc """
  Runs a task: allocates the vehicles the script picked to its platform
  tasks, runs it and returns `:ok` when it is done (`:stopped` if the
  operator stopped it). A map runs each task on its own vehicle set (`_`:
  any picked vehicle), all at the same time.

      execute until(survey, battery(v) < 0.3) >>> return_home
      execute %{v1 => survey_north, v2 => survey_south, _: photos}

  A failure stops the script, reported at the line of the `execute`
  (`execute failed: mission "Survey" (task 7, line 12) on vehicle 2 failed:
  vehicle 2 lost`), unless a `watch/2` handles it.
  """
  defmacro execute(task), do: at_line(quote(do: Dolphin.Script.Statements.execute(unquote(task))), __CALLER__)

  @doc """
  `execute action do ... end` means `execute(action do ... end)`: Elixir
  gives the `do` block to `execute`, which hands it on.

      execute action do
        message("up and away")
      end
  """
  defmacro execute({name, meta, args}, do: block) when is_atom(name) and (is_atom(args) or args == []),
    do: at_line(quote(do: Dolphin.Script.Statements.execute(unquote({name, meta, [[do: block]]}))), __CALLER__)

  defmacro execute(other, do: _block),
    do: raise(ArgumentError, "execute with a do block takes a word such as `action`, got: #{Macro.to_string(other)}")

  @doc """
  Runs the block for ever: until the script is stopped (`--for`, the
  operator), halts or fails.

      forever do
        v = pick(type: :uav)
        execute until(survey, battery(v) < 0.3) >>> return_home |> on(v)
        release(v)
      end
  """
  defmacro forever(do: block), do: quote(do: Dolphin.Script.Statements.forever(fn -> unquote(block) end))

  @doc """
  Runs `fun` for ever, each round given what the previous one returned
  (the first: `state`).

      forever(pick(type: :uav), fn flying ->
        spare = pick(type: :uav)
        execute until(survey, battery(flying) < 0.3) |> on(flying)
        release(flying)
        spare
      end)
  """
  defdelegate forever(state, fun), to: Statements

  @doc """
  Runs the block `n` times; `:ok`. Raises `ArgumentError` unless `n` is a
  non-negative integer.

      repeat 3 do
        execute survey >>> return_home
      end
  """
  defmacro repeat(n, do: block), do: quote(do: Dolphin.Script.Statements.repeat(unquote(n), fn -> unquote(block) end))

  @doc """
  An operator log line (`message: text` in the output of `mix dolphin.run`,
  a `message` event); not a string: `inspect`ed. `:ok`.

      message("Done!")
  """
  defdelegate message(text), to: Statements

  @doc """
  Adds `value` to the script's signal `key`, shared by all its tasks; `:ok`.
  Conditions that poll `key` are evaluated again.

      action do post(:target_found, position(v)) end
  """
  defdelegate post(key, value), to: Statements

  @doc """
  Removes `value` from signal `key`: `true` if it was there, else `false`.

      if consume(:charged, v), do: execute survey |> on(v)
  """
  defdelegate consume(key, value), to: Statements

  @doc """
  Whether signal `key` has a value.

      execute wait_for(poll(:target_found), then: circle)
  """
  defdelegate poll(key), to: Statements

  @doc """
  Whether signal `key` has a value for which `fun` is truthy.

      execute wait_for(poll(:found, fn p -> contains?(zone, p) end), then: circle)
  """
  defdelegate poll(key, fun), to: Statements

  @doc """
  Pauses the script for `d` ms of clock time; `:ok`.

      pause(seconds(10))
  """
  defdelegate pause(d), to: Statements

  @doc """
  Stops the script and all its tasks (vehicles hold): the run ends with
  `FILE:LINE: halted: text` and exit status 1. Works from inside an action.

      if battery(v) < 0.5, do: halt("not enough battery to start")
  """
  defmacro halt(text \\ "halted"), do: at_line(quote(do: Dolphin.Script.Statements.halt(unquote(text))), __CALLER__)

  @doc """
  Asks the operator: prints `prompt`, returns the line typed (without its
  newline), `nil` at the end of input.

      if ask("Fly? (y/n)") == "y", do: execute survey
  """
  defdelegate ask(prompt), to: Statements

  @doc """
  A vehicle's parameter (the PARAM micro-service), by name, typed: an
  integer for the integer types, a float otherwise. A statement, not a
  condition's reader (it asks the vehicle and waits for its answer). A
  name the vehicle does not have fails the script at this line, naming the
  ones near (`vehicle 1 has no parameter WPNAV_SPED (did you mean WPNAV_SPEED?)`).

      speed = param(v, "WPNAV_SPEED")
  """
  defmacro param(v, name), do: at_line(quote(do: Dolphin.Script.Statements.param(unquote(v), unquote(name))), __CALLER__)

  @doc """
  Sets a vehicle's parameter and reads it back; returns the value kept. A
  value the vehicle keeps otherwise (a whole number for an integer type), or a name it does
  not have, fails the script at this line.

      set_param(v, "WPNAV_SPEED", 800)
  """
  defmacro set_param(v, name, value), do: at_line(quote(do: Dolphin.Script.Statements.set_param(unquote(v), unquote(name), unquote(value))), __CALLER__)

  @doc """
  Sends a raw MAVLink message struct to every vehicle of `set`; `:ok`.

      send_message(v, %Dolphin.MAVLink.Ardupilotmega.CommandLong{command: 183, param1: 9.0, param2: 1900.0})
  """
  defdelegate send_message(set, message), to: Statements
end
