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

  @doc false
  # The seconds to add to an event's `t_ms / 1000` to put it on the log's time
  # line. `log` is the log's anchors: %{vehicles: [id], span_s: s, speedup: k, arming: %{id
  # => [t]}, modes: %{id => [{t, mode}]}, reached: %{id => [{t, seq}]}, cut: bool}.
  @spec align([map()], map(), Path.t()) :: {:ok, float()} | {:error, Error.t()}
  def align([], _log, _path), do: {:ok, 0.0}

  def align(events, log, path) do
    foreign = events |> Enum.flat_map(&vehicles/1) |> Enum.uniq() |> Enum.reject(&(&1 in log.vehicles)) |> Enum.sort()
    diffs = anchors(events, log)

    cond do
      foreign != [] ->
        mismatch(path, "its vehicles #{Enum.join(foreign, ", ")} are not in the telemetry log (which has #{Enum.join(log.vehicles, ", ")})")

      diffs != [] ->
        offset = median(diffs)
        agree = Enum.count(diffs, &(abs(&1 - offset) <= @tolerance_s))

        if agree * 2 < length(diffs),
          do: mismatch(path, "only #{agree} of #{length(diffs)} arming, mode and mission-item events line up with the telemetry log's frames"),
          else: overlap(events, offset, log, path)

      true ->
        overlap(events, 0.0, log, path)
    end
  end

  # Both files start when the run starts and end when it ends (the log a
  # little later: the vehicles and links stop after the script, a few real
  # seconds); events far outside the log's time are another run's. A log cut
  # short may end before the events do.
  defp overlap(events, offset, log, path) do
    first = hd(events)["t_ms"] / 1000 + offset
    last = List.last(events)["t_ms"] / 1000 + offset
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
        {:ok, offset}
    end
  end

  defp mismatch(path, why), do: {:error, %Error{reason: :events_mismatch, path: path, detail: "these events are from another run: " <> why}}

  defp vehicles(%{"vehicle" => v}) when is_integer(v), do: [v]
  defp vehicles(%{"vehicles" => vs}) when is_list(vs), do: Enum.filter(vs, &is_integer/1)
  defp vehicles(_), do: []

  # The nth arming (mode, item) of a vehicle in the events against the nth in
  # the log: the differences of their times.
  defp anchors(events, log) do
    by = fn name -> events |> Enum.filter(&(&1["event"] == name)) |> Enum.group_by(& &1["vehicle"]) end

    armed =
      for {v, es} <- by.("armed"), {e, t} <- Enum.zip(es, Map.get(log.arming, v, [])), do: t - e["t_ms"] / 1000

    modes =
      for {v, es} <- by.("mode_changed"),
          {mode, group} <- Enum.group_by(es, & &1["mode"]),
          logged = for({t, m} <- Map.get(log.modes, v, []), to_string(m) == mode, do: t),
          {e, t} <- Enum.zip(group, logged),
          do: t - e["t_ms"] / 1000

    reached =
      for {v, es} <- by.("mission_item_reached"),
          {seq, group} <- Enum.group_by(es, & &1["seq"]),
          logged = for({t, s} <- Map.get(log.reached, v, []), s == seq, do: t),
          {e, t} <- Enum.zip(group, logged),
          do: t - e["t_ms"] / 1000

    armed ++ modes ++ reached
  end

  defp median(xs) do
    sorted = Enum.sort(xs)
    Enum.at(sorted, div(length(sorted), 2))
  end
end
