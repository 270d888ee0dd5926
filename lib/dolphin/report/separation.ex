defmodule Dolphin.Report.Separation do
  @moduledoc """
  How close a flight log's vehicles came to each other: at each position a
  vehicle reported while in the air, the distance across to the nearest
  other vehicle within the vertical separation of it (one farther apart in
  height is apart whatever the distance across), with the others moved on
  by their velocities to that moment.

  What the flight report plots against the limit line, and what a test
  measures a run by:

      {:ok, log} = Dolphin.Report.FlightLog.read_file("logs/run.tlog")
      Dolphin.Report.Separation.closest(log).least
      # %{at_s: 61.2, across: 48.3, height: 0.2, pair: {1, 2}}
  """

  alias Dolphin.Report.FlightLog

  # Above this height above home a vehicle is flying (as the report's model judges it).
  @airborne_m 1.0
  # Beyond this many vehicles the pairs are not measured (a report of a big fleet would spend minutes on it).
  @max_vehicles 50

  @type result :: %{series: [{float(), float()}], least: nil | %{at_s: float(), across: float(), height: float(), pair: {term(), term()}}}

  @doc """
  The nearest-vehicle distance over time, in the log's clock seconds, and
  the least of it with its moment, height apart and pair (`nil` when no two
  vehicles were in the air within `vertical` metres in height of each
  other). Options: `:vertical` (metres, default 10).
  """
  @spec closest(FlightLog.t(), keyword()) :: result()
  def closest(%FlightLog{} = log, opts \\ []) do
    vertical = Keyword.get(opts, :vertical, Dolphin.Separation.default_limits().vertical)
    vehicles = Map.values(log.vehicles)

    if length(vehicles) < 2 or length(vehicles) > @max_vehicles or log.first_us == nil do
      %{series: [], least: nil}
    else
      k = FlightLog.speedup(log)
      clock = FlightLog.clock(log)
      {lat0, lon0} = origin(vehicles)
      plane = Dolphin.Geo.tangent_plane(%{lat: lat0, lon: lon0})

      vehicles
      |> Enum.flat_map(fn v -> samples(v, plane, k) end)
      |> Enum.sort()
      |> Enum.reduce({%{}, [], nil}, fn {ts, id, _, _} = sample, {latest, series, least} ->
        latest = Map.put(latest, id, sample)

        case nearest(sample, latest, vertical) do
          nil -> {latest, series, least}
          {across, height, other} -> {latest, [{clock.(ts), across} | series], lesser(least, clock.(ts), across, height, {id, other})}
        end
      end)
      |> then(fn {_, series, least} -> %{series: Enum.reverse(series), least: least} end)
    end
  end

  # {ts, id, {north, east, height}, {v_north, v_east}} of each position in the air.
  defp samples(v, plane, k) do
    home_m = if match?({_, _, _}, v.home), do: elem(v.home, 2) / 1000, else: 0.0

    for {ts, lat, lon, rel_mm, vx, vy} <- v.positions, rel_mm / 1000 > @airborne_m do
      {n, e} = Dolphin.Geo.to_tangent(plane, lat / 1.0e7, lon / 1.0e7)
      # Velocities are per clock second; timestamps real: k clock seconds per real one.
      {ts, v.id, {n, e, home_m + rel_mm / 1000}, {vx / 100 * k, vy / 100 * k}}
    end
  end

  defp nearest({ts, id, {n, e, h}, _}, latest, vertical) do
    latest
    |> Enum.flat_map(fn
      {^id, _} ->
        []

      {other, {ts0, _, {n0, e0, h0}, {vn, ve}}} ->
        dt = (ts - ts0) / 1_000_000
        {dn, de} = {n0 + vn * dt - n, e0 + ve * dt - e}
        if abs(h0 - h) < vertical, do: [{:math.sqrt(dn * dn + de * de), abs(h0 - h), other}], else: []
    end)
    |> Enum.min(fn -> nil end)
  end

  defp lesser(nil, t, across, height, pair), do: %{at_s: t, across: across, height: height, pair: pair}
  defp lesser(%{across: least} = l, _t, across, _height, _pair) when least <= across, do: l
  defp lesser(_l, t, across, height, pair), do: %{at_s: t, across: across, height: height, pair: pair}

  defp origin(vehicles) do
    Enum.find_value(vehicles, {0.0, 0.0}, fn
      %{positions: [{_, lat, lon, _, _, _} | _]} -> {lat / 1.0e7, lon / 1.0e7}
      _ -> nil
    end)
  end
end
