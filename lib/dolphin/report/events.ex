defmodule Dolphin.Report.Events do
  @moduledoc false
  # Reads a run's JSONL events (Dolphin.Events.Writer) and places them on
  # the telemetry log's time line, refusing the events of another run.
  #
  # The events file carries no run id and no wall-clock time: `t_ms` is clock
  # time since the writer started, the log's stamps are wall-clock time. So
  # the two are matched by what both record: a vehicle arming, changing mode,
  # reaching a mission item is an event and a frame of the log. Their time
  # differences give the offset; events whose vehicles are not in the log, or
  # whose arming, modes and items do not line up with the log's, or that do
  # not overlap it in time, are another run's. (Two runs alike in all of that,
  # a deterministic simulation run twice, cannot be told apart.)

  alias Dolphin.Report.Error

  # Clock seconds within which an event and its frame are the same moment:
  # heartbeats come once a second and a sped-up link stamps frames late.
  @tolerance_s 3.0
  # Anchors this many seconds apart, or more, measure the rate of one time
  # line against the other (the tolerance above is small beside it).
  @rate_span_s 20.0
  # The most anchors the rate is measured on (pairs of them: the square).
  @rate_anchors 200
  # The vehicles' pace against the clock asked for: a tenth of it at worst,
  # and no faster than a quarter more (a boot clock's jitter).
  @least_rate 0.1
  # A rate other than 1 is measured on no fewer anchors than this.
  @rated_least_anchors 4
  @most_rate 1.25
  # A time line through the anchors themselves (a pace that swung) is taken
  # on no fewer anchors than this, and the most it is worked out on.
  @piecewise_least_anchors 6
  @piecewise_anchors 1_000
  # Clock seconds, and real seconds at the run's speed-up, that starting a
  # run's links and vehicles may take.
  @start_s 30.0
  @start_real_s 20.0

  @doc false
  @spec read_file(Path.t()) :: {:ok, [map()], non_neg_integer()} | {:error, Error.t()}
  def read_file(path) do
    case File.read(path) do
      {:ok, text} ->
        {events, bad} =
          text
          |> String.split("\n", trim: true)
          |> Enum.reduce({[], 0}, fn line, {acc, bad} ->
            case decode(line) do
              {:ok, %{"event" => name, "t_ms" => t} = e} when is_binary(name) and is_number(t) -> {[e | acc], bad}
              _ -> {acc, bad + 1}
            end
          end)

        # A file with no event is not a run's events (another kind of file,
        # or the wrong one): an error, not a report without events.
        case events do
          [] when bad == 0 -> {:error, %Error{reason: :no_events, path: path, detail: "the file is empty"}}
          [] -> {:error, %Error{reason: :no_events, path: path, detail: "none of its #{bad} line(s) is an event (a JSON line as mix dolphin.run --events writes it)"}}
          _ -> {:ok, events |> Enum.reverse() |> Enum.sort_by(& &1["t_ms"]), bad}
        end

      {:error, why} ->
        {:error, %Error{reason: :events_unreadable, path: path, detail: :file.format_error(why) |> to_string()}}
    end
  end

  defp decode(line) do
    {:ok, :jiffy.decode(line, [:return_maps, null_term: nil])}
  catch
    # jiffy throws {:error, {position, reason}} on malformed JSON (a line cut
    # short when the run was killed, say): that line is skipped and counted.
    :throw, {:error, reason} -> {:error, reason}
    :error, reason -> {:error, reason}
  end

  @typedoc false
  # `{scale, offset}`: an event at `t_ms` is at `scale * t_ms / 1000 +
  # offset` seconds of the log's clock; `{:piecewise, knots}`: straight
  # between the knots, `[{event s, log s}]` rising in both, and at their
  # overall rate beyond them.
  @type timeline :: {float(), float()} | {:piecewise, [{float(), float()}]}

  @doc false
  # Where the events go on the log's time line (a timeline(), see place/2).
  # The log's clock is the vehicles' own (their boot clocks against the
  # log's stamps); the events' is the ground station's, which runs at the
  # speed-up asked for. A vehicle that cannot keep that pace (ArduCopter SITL
  # on a loaded machine, at half its speed-up) falls behind it, so the two
  # time lines differ in rate as well as in origin: both are fitted. A pace
  # that swung during the run (ArduCopter SITL beside other work went from
  # 6.2x to 10.6x of its 10x and back within seconds) fits no one rate: the
  # time line then runs through the anchors themselves, the longest chain of
  # them that rises at a pace a vehicle can have. `log` is the log's anchors:
  # %{vehicles: [id], span_s: s, speedup: k, arming: %{id => [t]}, modes:
  # %{id => [{t, mode}]}, reached: %{id => [{t, seq}]}, heard: %{id => t},
  # cut: bool}.
  @spec align([map()], map(), Path.t()) :: {:ok, timeline()} | {:error, Error.t()}
  def align([], _log, _path), do: {:ok, {1.0, 0.0}}

  def align(events, log, path) do
    foreign = events |> Enum.flat_map(&vehicles/1) |> Enum.uniq() |> Enum.reject(&(&1 in log.vehicles)) |> Enum.sort()
    pairs = anchors(events, log)

    cond do
      foreign != [] ->
        mismatch(path, "its vehicles #{Enum.join(foreign, ", ")} are not in the telemetry log (which has #{Enum.join(log.vehicles, ", ")})")

      pairs != [] ->
        n = length(pairs)
        {rated, rated_agree} = fit(pairs, rate(pairs))
        {plain, plain_agree} = fit(pairs, 1.0)

        # Two free numbers fit a few scattered anchors more easily than one:
        # a rate of its own is taken only when nearly all anchors agree with it.
        cond do
          n >= @rated_least_anchors and rated_agree >= 0.8 * n ->
            overlap(events, rated, log, path)

          plain_agree * 2 >= n ->
            overlap(events, plain, log, path)

          true ->
            # Nearly all anchors on one chain, as nearly all must agree with a rate.
            case chain(pairs) do
              {knots, sampled} when sampled >= @piecewise_least_anchors and length(knots) >= 0.8 * sampled ->
                overlap(events, {:piecewise, rising(knots)}, log, path)

              _ ->
                mismatch(path, "only #{max(plain_agree, rated_agree)} of #{n} arming, mode and mission-item events line up with the telemetry log's frames")
            end
        end

      true ->
        overlap(events, {1.0, starting(events, log)}, log, path)
    end
  end

  # Without an arming, a mode or an item to go by, the vehicles' discovery
  # (an event, and their first heartbeat in the log) places the events,
  # if it came within what starting a run takes: the clock runs from the
  # events file's first line while the links and vehicles start, which
  # on a loaded machine at a high speed-up is a minute of clock time or
  # more. Later than that, the events are left where they begin, for the
  # overlap to judge.
  defp starting(events, log) do
    offsets = for %{"event" => "vehicle_discovered", "vehicle" => v, "t_ms" => t} <- events, heard = log.heard[v], do: heard - t / 1000

    case offsets do
      [] -> 0.0
      _ -> offsets |> median() |> then(&if(-&1 <= @start_s + @start_real_s * log.speedup, do: &1, else: 0.0))
    end
  end

  # The log's seconds per event second: the median of the slopes between
  # anchors far enough apart in time to measure one (Theil and Sen's
  # estimator: a few anchors off by a heartbeat do not move it). 1.0 when
  # they are too few or too close; never outside what a vehicle's pace can
  # be against the clock asked for (it falls behind, it does not run far
  # ahead).
  defp rate(pairs) do
    sample = pairs |> Enum.sort() |> take_every(max(1, div(length(pairs), @rate_anchors)))

    slopes = for {{e1, t1}, i} <- Enum.with_index(sample), {e2, t2} <- Enum.drop(sample, i + 1), e2 - e1 >= @rate_span_s, do: (t2 - t1) / (e2 - e1)

    case slopes do
      [] -> 1.0
      _ -> slopes |> median() |> max(@least_rate) |> min(@most_rate)
    end
  end

  # The time line at `scale` through the anchors, and how many of them agree with it.
  defp fit(pairs, scale) do
    offset = median(for {e, t} <- pairs, do: t - scale * e)
    {{scale, offset}, Enum.count(pairs, fn {e, t} -> abs(t - (scale * e + offset)) <= @tolerance_s end)}
  end

  # The longest chain of anchors, in the order of the events, each the
  # next's at a pace a vehicle can have (@least_rate to @most_rate, give or
  # take a heartbeat's lateness each): anchors paired wrongly (the nth mode
  # change of the events with another one of the log) fall off it. Worked out
  # on at most @piecewise_anchors of them, evenly spread: `{chain, how many}`.
  defp chain(pairs) do
    sample = pairs |> Enum.sort() |> take_every(max(1, ceil(length(pairs) / @piecewise_anchors)))

    {{_, best}, _} =
      Enum.reduce(sample, {{0, []}, []}, fn {e, t} = anchor, {best, chains} ->
        # chains: the longest chain ending at each anchor so far, {length,
        # anchors newest first}, newest first.
        {n, longest} =
          chains
          |> Enum.filter(fn {_, [{e0, t0} | _]} -> follows?(e - e0, t - t0) end)
          |> Enum.max_by(&elem(&1, 0), fn -> {0, []} end)

        mine = {n + 1, [anchor | longest]}
        {if(n + 1 > elem(best, 0), do: mine, else: best), [mine | chains]}
      end)

    {Enum.reverse(best), length(sample)}
  end

  defp follows?(de, dt), do: dt >= @least_rate * de - @tolerance_s and dt <= @most_rate * de + @tolerance_s

  # Knots for a time line: each later than the one before on both (anchors of
  # one moment a heartbeat apart may not be).
  defp rising([first | rest]) do
    rest
    |> Enum.reduce([first], fn {e, t}, [{e0, t0} | _] = acc -> if e > e0 and t > t0, do: [{e, t} | acc], else: acc end)
    |> Enum.reverse()
  end

  @doc false
  # Where an event at `t_ms` of the events' clock is on the log's (seconds).
  @spec place(timeline(), number()) :: float()
  def place({:piecewise, [{e0, _} | _] = knots}, t_ms) do
    e = t_ms / 1000
    if e < e0, do: beyond(knots, hd(knots), e), else: along(knots, e, knots)
  end

  def place({scale, offset}, t_ms), do: scale * t_ms / 1000 + offset

  defp along([{a, ta}, {b, tb} | _], e, _knots) when e <= b, do: ta + (e - a) * (tb - ta) / (b - a)
  defp along([_ | [_ | _] = rest], e, knots), do: along(rest, e, knots)
  defp along([last], e, knots), do: beyond(knots, last, e)

  # Before the first knot or after the last: from that knot at the knots'
  # overall rate (1 for a single knot).
  defp beyond([{e0, t0} | _] = knots, {ek, tk}, e) do
    {el, tl} = List.last(knots)
    rate = if el > e0, do: (tl - t0) / (el - e0), else: 1.0
    tk + (e - ek) * rate
  end

  defp take_every(list, 1), do: list
  defp take_every(list, n), do: Enum.take_every(list, n)

  # Both files start when the run starts and end when it ends (the log a
  # little later: the vehicles and links stop after the script, a few real
  # seconds); events far outside the log's time are another run's. A log cut
  # short may end before the events do.
  defp overlap(events, timeline, log, path) do
    first = place(timeline, hd(events)["t_ms"])
    last = place(timeline, List.last(events)["t_ms"])
    slack = max(30.0, 0.2 * log.span_s)
    teardown = 30.0 + 0.1 * log.span_s + 5.0 * log.speedup
    finished = Enum.any?(events, &(&1["event"] == "script_finished"))

    cond do
      first > log.span_s + slack or last < -slack ->
        mismatch(path, "its #{round(last - first)} s do not overlap the telemetry log's #{round(log.span_s)} s")

      not log.cut and last - first > log.span_s + slack ->
        mismatch(path, "it spans #{round(last - first)} s, the telemetry log #{round(log.span_s)} s")

      finished and not log.cut and log.span_s - last > teardown ->
        mismatch(path, "its script ended #{round(log.span_s - last)} s before the end of the telemetry log (of #{round(log.span_s)} s)")

      true ->
        {:ok, timeline}
    end
  end

  defp mismatch(path, why), do: {:error, %Error{reason: :events_mismatch, path: path, detail: "these events are from another run: " <> why}}

  defp vehicles(%{"vehicle" => v}) when is_integer(v), do: [v]
  defp vehicles(%{"vehicles" => vs}) when is_list(vs), do: Enum.filter(vs, &is_integer/1)
  defp vehicles(_), do: []

  # The nth arming (mode, item) of a vehicle in the events against the nth in
  # the log: their times, {event's, log's}.
  defp anchors(events, log) do
    by = fn name -> events |> Enum.filter(&(&1["event"] == name)) |> Enum.group_by(& &1["vehicle"]) end

    armed = for {v, es} <- by.("armed"), {e, t} <- Enum.zip(es, Map.get(log.arming, v, [])), do: {e["t_ms"] / 1000, t}

    modes =
      for {v, es} <- by.("mode_changed"),
          {mode, group} <- Enum.group_by(es, & &1["mode"]),
          logged = for({t, m} <- Map.get(log.modes, v, []), to_string(m) == mode, do: t),
          {e, t} <- Enum.zip(group, logged),
          do: {e["t_ms"] / 1000, t}

    reached =
      for {v, es} <- by.("mission_item_reached"),
          {seq, group} <- Enum.group_by(es, & &1["seq"]),
          logged = for({t, s} <- Map.get(log.reached, v, []), s == seq, do: t),
          {e, t} <- Enum.zip(group, logged),
          do: {e["t_ms"] / 1000, t}

    armed ++ modes ++ reached
  end

  defp median(xs) do
    sorted = Enum.sort(xs)
    Enum.at(sorted, div(length(sorted), 2))
  end
end
