defmodule Dolphin.Console.Vehicle do
  @moduledoc false
  # The console's vehicle helpers behind `Dolphin.Console` (which holds their
  # docs): commands, manoeuvres, mission transfers and watching one vehicle,
  # each through one common path of checks (`command/5`).

  alias Dolphin.{Clock, Console, Engine, ManoeuvreError, Mission, Vehicles}
  alias Dolphin.Vehicles.{Manoeuvres, ParamProtocol}
  alias Dolphin.Console.{Arguments, EventLog, Format, MissionSource, Overview}

  # What IEx does not print (IEx.dont_display_result/0): the helpers print for themselves.
  defp done, do: IEx.dont_display_result()

  defp say(text), do: IO.puts(text)

  # --- commands ------------------------------------------------------------

  @spec arm(Console.vehicle_id(), keyword()) :: Console.printed()
  def arm(id, opts \\ []) do
    command(id, :control, opts, [:force, :wait], fn view, opts ->
      cond do
        view.armed? -> say("vehicle #{id} is armed already")
        view.mode == :auto -> say("vehicle #{id} is in AUTO, where ArduCopter does not arm: mode(#{id}, :guided) first")
        true -> with_wait(id, opts, &finish(id, Manoeuvres.arm_when_ready(id, within: &1, report: reporter(id)), nil))
      end
    end)
  end

  # The `wait:` of arm/2 and takeoff/3, checked before anything is sent.
  defp with_wait(id, opts, fun) do
    case Arguments.ms(Keyword.get(opts, :wait, 30_000), :wait) do
      {:ok, wait} -> fun.(wait)
      {:error, why} -> say("vehicle #{id}: " <> why_text(why))
    end
  end

  # Prints the steps of a manoeuvre (Dolphin.Vehicles.Manoeuvres) as the
  # vehicle accepts them, and each new refusal it will try again.
  defp reporter(id, altitude \\ nil) do
    fn
      {:accepted, step} ->
        say("vehicle #{id}: #{step(step, altitude)} accepted")

      {:refused, step, e, texts, left_ms} ->
        say("vehicle #{id}: #{step(step, altitude)} refused (#{Exception.message(e)}#{news(texts)}); trying again until #{Format.duration(left_ms)} from now")
    end
  end

  # The refusal that ended a manoeuvre; the steps before it were printed.
  defp finish(_id, :ok, _altitude), do: :ok

  defp finish(id, {:error, %ManoeuvreError{} = e}, altitude) do
    step = %{"switching to GUIDED" => :guided, "arming" => :arm, "take-off" => :take_off} |> Map.get(e.action, e.action)
    say("vehicle #{id}: #{step(step, altitude)} refused: #{Exception.message(e.refusal)}#{news(e.texts)}")
    :error
  end

  defp step(:guided, _altitude), do: "mode GUIDED"
  defp step(:arm, _altitude), do: "arm"
  defp step(:take_off, altitude), do: "take-off to #{Format.metres(altitude)} above home"
  defp step(action, _altitude), do: action

  defp texts(id), do: Vehicles.status_texts(id)

  # The vehicle's STATUSTEXTs that came with an answer, as " — text; text".
  defp news([]), do: ""
  defp news(new), do: " — " <> Enum.map_join(new, "; ", &elem(&1, 1))

  @spec disarm(Console.vehicle_id(), keyword()) :: Console.printed()
  def disarm(id, opts \\ []) do
    command(id, :control, opts, [:force], fn view, _opts ->
      cond do
        not view.armed? -> say("vehicle #{id} is disarmed already")
        Manoeuvres.in_air?(view) -> say("vehicle #{id} is in the air: disarming would make it fall; land(#{id}) lands it and it disarms on the ground")
        true -> result(id, "disarm", fn -> Vehicles.disarm(id) end)
      end
    end)
  end

  @spec mode(Console.vehicle_id(), atom() | String.t(), keyword()) :: Console.printed()
  def mode(id, mode, opts \\ []) do
    case Arguments.mode(mode) do
      {:ok, mode} ->
        command(id, :control, opts, [:force], fn view, opts ->
          case Arguments.pilot_mode(mode, Manoeuvres.in_air?(view), opts[:force] == true) do
            :ok -> result(id, "mode #{Format.mode(mode)}", fn -> Vehicles.set_mode(id, mode) end)
            {:error, why} -> say("vehicle #{id}: " <> why_text(why))
          end
        end)

      {:error, why} ->
        say("mode: " <> why_text(why))
        done()
    end
  end

  @spec takeoff(Console.vehicle_id(), number(), keyword()) :: Console.printed()
  def takeoff(id, altitude, opts \\ []) do
    case Arguments.altitude(altitude) do
      {:ok, alt} ->
        command(id, :control, opts, [:force, :wait], fn view, opts ->
          if Manoeuvres.in_air?(view) do
            say("vehicle #{id} is flying already (#{Format.metres(view.relative_altitude)} above home): goto(#{id}, lat, lon, alt) moves it")
          else
            with_wait(id, opts, &finish(id, Manoeuvres.take_off(id, alt, within: &1, report: reporter(id, alt)), alt))
          end
        end)

      {:error, why} ->
        say("takeoff: " <> why_text(why))
        done()
    end
  end

  @spec goto(Console.vehicle_id(), number(), number(), number(), keyword()) :: Console.printed()
  def goto(id, lat, lon, altitude, opts \\ []) do
    case Arguments.position(lat, lon, altitude) do
      {:ok, point} ->
        command(id, :control, opts, [:force, :amsl], fn view, opts ->
          ref = if opts[:amsl], do: "AMSL", else: "above home"

          if Manoeuvres.in_air?(view) do
            result(id, "go to #{Format.position(lat, lon)} at #{Format.metres(altitude)} #{ref}", fn -> Manoeuvres.go_to(id, point, amsl: opts[:amsl]) end)
          else
            say("vehicle #{id} is not in the air: takeoff(#{id}, altitude) first")
          end
        end)

      {:error, why} ->
        say("goto: " <> why_text(why))
        done()
    end
  end

  @spec hold(Console.vehicle_id(), keyword()) :: Console.printed()
  def hold(id, opts \\ []) do
    command(id, :control, opts, [:force], fn view, _opts ->
      case Manoeuvres.hold(id) do
        :ok ->
          cond do
            not view.armed? -> say("vehicle #{id} is disarmed: nothing to hold")
            view.mode in [:brake, :guided] -> say("vehicle #{id} holds already (#{Format.mode(view.mode)})")
            true -> say("vehicle #{id}: holding position (was #{Format.mode(view.mode)})")
          end

        {:error, e} ->
          say("vehicle #{id}: hold failed: #{Exception.message(e)}")
      end
    end)
  end

  @spec rtl(Console.vehicle_id(), keyword()) :: Console.printed()
  def rtl(id, opts \\ []), do: command(id, :control, opts, [:force], fn _state, _ -> result(id, "return to launch", fn -> Vehicles.return_to_launch(id) end) end)

  @spec land(Console.vehicle_id(), keyword()) :: Console.printed()
  def land(id, opts \\ []), do: command(id, :control, opts, [:force], fn _state, _ -> result(id, "land", fn -> Manoeuvres.land(id) end) end)

  @spec upload(Console.vehicle_id(), Mission.t() | Path.t(), keyword()) :: Console.printed()
  def upload(id, mission, opts \\ []) do
    case load_mission(mission) do
      {:ok, mission} ->
        command(id, :control, opts, [:force], fn view, _opts ->
          home = mission.home || view.home

          case items(mission, home) do
            {:ok, items} ->
              case Vehicles.upload_mission(id, items) do
                :ok -> say("vehicle #{id}: mission #{inspect(mission.name)} uploaded (#{length(items)} items, home included)")
                {:error, e} -> say("vehicle #{id}: upload failed: " <> Exception.message(e))
              end

            {:error, why} ->
              say("upload: " <> why)
          end
        end)

      {:error, why} ->
        say("upload: " <> why)
        done()
    end
  end

  defp load_mission(%Mission{} = m), do: {:ok, m}

  defp load_mission(path) when is_binary(path) do
    with {:ok, json} <- File.read(path) |> file_error(path),
         {:ok, m} <- Mission.from_plan(json, name: Path.basename(path, ".plan")) |> plan_error(path),
         do: {:ok, m}
  end

  defp load_mission(other), do: {:error, "a mission is a %Dolphin.Mission{} or a .plan file's path, got: #{inspect(other, limit: 5)}"}

  defp file_error({:error, why}, path), do: {:error, "#{path}: #{:file.format_error(why)}"}
  defp file_error(ok, _path), do: ok
  defp plan_error({:error, e}, path), do: {:error, "#{path}: #{Exception.message(e)}"}
  defp plan_error(ok, _path), do: ok

  defp items(mission, home) do
    {:ok, if(home, do: Mission.to_items(mission, home: home), else: Mission.to_items(mission))}
  rescue
    e in ArgumentError -> {:error, Exception.message(e)}
  end

  @spec download(Console.vehicle_id(), keyword()) :: Console.printed()
  def download(id, opts \\ []) do
    command(id, :link, opts, [:save], fn _state, opts ->
      case Vehicles.download_mission(id) do
        {:ok, [_home]} ->
          say("vehicle #{id} has no mission (only its home)")

        {:ok, items} ->
          say(holds(id, length(items) - 1))
          say(Format.items(items))

          case MissionSource.from_items(items, "vehicle #{id}") do
            {:ok, mission} ->
              say("\n" <> MissionSource.to_source(mission))
              if path = opts[:save], do: save_plan(mission, path)

            {:error, e} ->
              say("(not readable as a mission: #{Exception.message(e)})")
          end

        {:error, e} ->
          say("vehicle #{id}: download failed: " <> Exception.message(e))
      end
    end)
  end

  # The heading of the table below it: as many items as rows, home first.
  defp holds(id, 1), do: "vehicle #{id} holds 2 items: home (item 0) and 1 mission item (item 1)"
  defp holds(id, n), do: "vehicle #{id} holds #{n + 1} items: home (item 0) and #{n} mission items (items 1 to #{n})"

  defp save_plan(mission, path) do
    case File.write(path, Mission.to_plan(mission)) do
      :ok -> say("saved as #{path}")
      {:error, why} -> say("cannot write #{path}: #{:file.format_error(why)}")
    end
  end

  # --- watching ---------------------------------------------------------------------

  @spec watch(Console.vehicle_id(), keyword()) :: Console.printed()
  def watch(id, opts \\ []) do
    command(id, :link, opts, [:every, :timeout, :keys], fn _view, opts ->
      every = Keyword.get(opts, :every, 1_000)
      timeout = Keyword.get(opts, :timeout, 60_000)

      if not (is_integer(every) and every > 0 and is_integer(timeout) and timeout >= 0) do
        say("watch: every: and timeout: are milliseconds, got: #{inspect(every)}, #{inspect(timeout)}")
      else
        reader = if Keyword.get(opts, :keys, true), do: key_reader()
        say("watching vehicle #{id} (#{if reader, do: "Enter stops, ", else: ""}stops by itself after #{Format.duration(timeout)})")
        start = System.monotonic_time(:millisecond)
        why = tick(id, Vehicles.status_texts(id), reader, start, start + timeout, every)
        if reader, do: stop_reader(reader)
        say("watch ended (#{why})")
      end
    end)
  end

  # Reads a line of the console in its own process: the watch goes on until
  # it comes. Linked: a watch that ends any other way (an exception, its
  # caller's exit) leaves no reader behind to take the next line typed.
  defp key_reader do
    me = self()
    gl = Process.group_leader()
    spawn_link(fn -> send(me, {:watch_key, self(), IO.gets(gl, "")}) end)
  end

  defp stop_reader(reader) do
    Process.unlink(reader)
    Process.exit(reader, :kill)
  end

  defp tick(id, texts, reader, start, deadline, every) do
    case Vehicles.state(id) do
      {:ok, state} ->
        for {_sev, text} <- Enum.reverse(Format.new_texts(texts, state.status_texts)), do: say("        >> " <> text)
        say(Format.ticker(state, lost?(id), System.monotonic_time(:millisecond) - start))
        next = min(System.monotonic_time(:millisecond) + every, deadline)

        case pause(reader, next) do
          :key -> "key pressed"
          {:continue, reader} -> if next >= deadline, do: "timeout", else: tick(id, state.status_texts, reader, start, deadline, every)
        end

      {:error, _} ->
        "vehicle #{id} is gone"
    end
  end

  defp lost?(id), do: match?({:ok, %{connected?: false}}, Vehicles.view(id))

  # Waits until `until` (monotonic ms) or a line typed on the console.
  defp pause(reader, until) do
    receive do
      {:watch_key, ^reader, line} when is_binary(line) -> :key
      # No keyboard (input closed): only the timeout ends the watch.
      {:watch_key, ^reader, _eof} -> pause(nil, until)
    after
      max(until - System.monotonic_time(:millisecond), 0) -> {:continue, reader}
    end
  end

  @spec messages(Console.vehicle_id()) :: Console.printed()
  def messages(id) do
    command(id, :any, [], [], fn view, _ ->
      unless view.connected?, do: say("vehicle #{id} is lost; its last messages:")
      say(Format.messages(Vehicles.status_texts(id)))
    end)
  end

  @spec param(Console.vehicle_id(), String.t()) :: Console.printed()
  def param(id, name) do
    command(id, :any, [], [], fn _view, _ ->
      case Vehicles.param(id, to_string(name), nil, []) do
        {:ok, value} -> say("vehicle #{id}: #{name} = #{ParamProtocol.show(value)}")
        {:error, e} -> say(Exception.message(e))
      end
    end)
  end

  @spec set_param(Console.vehicle_id(), String.t(), number()) :: Console.printed()
  def set_param(id, name, value) do
    command(id, :any, [], [], fn _view, _ ->
      cond do
        not is_number(value) -> say("set_param takes a number, got: #{inspect(value)}")
        true -> param_answer(id, name, Vehicles.param(id, to_string(name), value, []))
      end
    end)
  end

  defp param_answer(id, name, {:ok, kept}), do: say("vehicle #{id}: #{name} set to #{ParamProtocol.show(kept)}")
  defp param_answer(_id, _name, {:error, e}), do: say(Exception.message(e))

  @spec params(Console.vehicle_id(), String.t()) :: Console.printed()
  def params(id, filter \\ "") do
    command(id, :any, [], [], fn _view, _ ->
      case Vehicles.param_list(id) do
        {:ok, list} ->
          shown = Enum.filter(list, &String.contains?(&1.name, to_string(filter)))
          Enum.each(ParamProtocol.listing(shown), &say/1)
          say("#{length(shown)} of #{length(list)} parameters")

        {:error, e} ->
          say(Exception.message(e))
      end
    end)
  end

  @spec events(pos_integer(), keyword()) :: Console.printed()
  def events(n \\ 20, opts \\ []) do
    with {:ok, n} <- Arguments.count(n),
         {:ok, opts} <- Arguments.options(opts, [:vehicle, :run, :event]) do
      names = opts[:event] && List.wrap(opts[:event])

      filter = fn e ->
        (names == nil or e.event in names) and
          (opts[:vehicle] == nil or Map.get(e, :vehicle) == opts[:vehicle] or opts[:vehicle] in List.wrap(Map.get(e, :vehicles))) and
          (opts[:run] == nil or Map.get(e, :run) == opts[:run])
      end

      case EventLog.last(n, filter) do
        [] -> say("no events#{if opts != [], do: " match", else: " yet"}")
        events -> say(Enum.map_join(events, "\n", &Dolphin.EventText.event_line(&1, EventLog.origin_ms())))
      end
    else
      {:error, why} -> say("events: " <> why_text(why))
    end

    done()
  end

  # --- the common path of vehicle helpers -------------------------------------------

  # Checks the id and the options, stops the vehicle's task if told to force,
  # then runs `fun` with the vehicle's view (Dolphin.Vehicles.View).
  defp command(id, needs, opts, allowed, fun) do
    # A vehicle named by its qualified name ("1@radio2") is the one that answers to it.
    id = Vehicles.resolve(id)

    with {:ok, opts} <- Arguments.options(opts, allowed),
         vehicles = Overview.vehicles(),
         {:ok, verdict} <- Arguments.vehicle(id, Overview.known(vehicles), needs, opts[:force] == true),
         :ok <- stop_first(id, verdict),
         {:ok, view} <- Vehicles.view(id) |> gone(id) do
      fun.(view, opts)
    else
      {:error, why} -> say(why_text(why))
    end

    done()
  end

  @doc false
  # The checks' and the runs' errors are structs; the helpers' own reasons are words.
  def why_text(%{__exception__: true} = e), do: Exception.message(e)
  def why_text(why) when is_binary(why), do: why

  defp gone({:ok, state}, _id), do: {:ok, state}
  defp gone(_, id), do: {:error, "vehicle #{id} went away"}

  defp stop_first(_id, :free), do: :ok

  defp stop_first(id, {:stop_first, task}) do
    say("vehicle #{id}: stopping task #{Format.task_label(task)} (run #{task.run}) first; the vehicle holds")
    _ = Engine.stop_task(task.task_id, :operator)
    # The task's stop makes the vehicle hold; bounded by the engine's stop timeout (15 s of clock time).
    deadline = System.monotonic_time(:millisecond) + Clock.to_real_ms(30_000) + 1_000
    await_gone(task.task_id, deadline)
  end

  defp await_gone(task_id, deadline) do
    cond do
      not Enum.any?(Engine.tasks(), &(&1.task_id == task_id)) -> :ok
      System.monotonic_time(:millisecond) > deadline -> {:error, "task #{task_id} did not stop in time: nothing sent"}
      true -> Process.sleep(20) == :ok and await_gone(task_id, deadline)
    end
  end

  # Runs a command or a one-command manoeuvre; says whether the vehicle
  # accepted it, with the messages it sent about it.
  defp result(id, what, fun) do
    before = texts(id)

    case fun.() do
      accepted when accepted in [:ok, {:ok, :accepted}] ->
        say("vehicle #{id}: #{what} accepted")
        :ok

      {:error, %ManoeuvreError{refusal: e, texts: said}} ->
        say("vehicle #{id}: #{what} refused: #{Exception.message(e)}#{news(said)}")
        :error

      {:error, e} ->
        say("vehicle #{id}: #{what} refused: #{Exception.message(e)}#{news(Format.new_texts(before, texts(id)))}")
        :error
    end
  end
end
