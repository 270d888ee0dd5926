defmodule Dolphin.Report.FlightLog do
  @moduledoc false
  # Reads a .tlog into what a flight report shows, one fold over its records:
  # per vehicle the positions, home, arming and modes, battery, link counters,
  # uploaded missions, items reached, photos and status texts.
  #
  # A log may hold several runs (logs appended to one another: each link
  # appends). A new run begins where the vehicles' boot clocks start again
  # after a silence of the whole log, when not even the ground station's own
  # heartbeat was recorded: the ground station was not running. (A vehicle
  # that reboots during a run restarts its clock too, but the ground station
  # goes on recording meanwhile.) `runs/1` lists them, `select/2` keeps one.

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.{Frame, Tlog}
  alias Dolphin.Vehicles.Modes

  import Bitwise

  @chunk 1_048_576
  @mav_type_gcs 6
  @mav_autopilot_invalid 8
  @mav_autopilot_px4 12
  @armed_flag 0x80
  # A gap in the vehicle's boot clock this long is a reboot or a silence, not
  # a measure of how fast its clock runs.
  @max_boot_step_ms 60_000
  # Real µs without any record that may separate two runs: the ground station
  # records its own heartbeat every second of clock time while it runs.
  @silence_us 2_000_000
  # How far (ms) a boot clock must go back to have started again, not to be
  # a frame overtaken on the way.
  @restart_ms 2_000

  defmodule Vehicle do
    @moduledoc false
    # One vehicle's records, newest first while reading (reversed by finish/1).
    defstruct id: nil,
              type: nil,
              autopilot: nil,
              home: nil,
              homes: [],
              positions: [],
              armed: nil,
              arming: [],
              mode: nil,
              modes: [],
              battery: [],
              link: [],
              uploads: [],
              # The latest fence and rally lists uploaded to it: seq => {command, x, y, z, param1}.
              fence: %{},
              rally: %{},
              reached: [],
              photos: [],
              texts: [],
              # Sensor readings: source => [{ts, raw value}] (see `read_file/2`'s :sensors).
              sensors: %{}
  end

  # `links`: per system id, {last seq, frames received, frames lost} of its
  # autopilot (kept apart from the vehicles: updated on every frame).
  # `previous_us`: the last record's stamp; `silence`: {first stamp after the
  # latest silence, last stamp before it}; `starts`: those of the silences
  # that began a run, newest first.
  # `sensors`: the sources to read, as `sensor_sources/1` indexes them.
  defstruct sensors: %{named: MapSet.new(), fields: %{}}, vehicles: %{}, links: %{}, first_us: nil, last_us: nil, boot_ms: 0, boot_real_us: 0, boot_last: %{}, stats: nil, previous_us: nil, silence: nil, starts: []

  @type t :: %__MODULE__{}

  @doc false
  # Option `sensors`: the sources of the sensors a run declared
  # (`Dolphin.Sensors.Sensor` sources), whose readings each vehicle keeps.
  @spec read_file(Path.t(), keyword()) :: {:ok, t()} | {:error, File.posix()}
  def read_file(path, opts \\ []) do
    case File.open(path, [:read, :binary, :raw, :read_ahead]) do
      {:ok, io} ->
        try do
          {:ok, read_io(io, Tlog.reader(unknown: :drop), %{new() | sensors: sensor_sources(Keyword.get(opts, :sensors, []))})}
        after
          File.close(io)
        end

      {:error, _} = error ->
        error
    end
  end

  defp read_io(io, reader, log) do
    case IO.binread(io, @chunk) do
      data when is_binary(data) ->
        {records, reader} = Tlog.read(reader, data)
        read_io(io, reader, Enum.reduce(records, log, &add/2))

      _eof_or_error ->
        {records, reader} = Tlog.finish(reader)
        finish(%{Enum.reduce(records, log, &add/2) | stats: Tlog.stats(reader)})
    end
  end

  @doc false
  @spec new() :: t()
  def new, do: %__MODULE__{}

  # Named values by name, message fields by message module.
  defp sensor_sources(sources) do
    Enum.reduce(sources, %{named: MapSet.new(), fields: %{}}, fn
      {:named_value, name}, acc -> %{acc | named: MapSet.put(acc.named, name)}
      {:message, module, field}, acc -> %{acc | fields: Map.update(acc.fields, module, [field], &[field | &1])}
    end)
  end

  @doc false
  # One record into the log.
  @spec add({non_neg_integer(), Frame.t()}, t()) :: t()
  def add({ts, %Frame{} = frame}, log) do
    silence = if log.previous_us && ts - log.previous_us >= @silence_us, do: {ts, log.previous_us}, else: log.silence
    log = %{log | first_us: log.first_us || ts, last_us: max(log.last_us || ts, ts), previous_us: ts, silence: silence, links: sequence(log.links, frame)}
    message(frame.message, ts, frame, sense(frame.message, ts, frame, log))
  end

  defp message(%M.Heartbeat{autopilot: ap, type: type} = hb, ts, frame, log) when ap != @mav_autopilot_invalid and type != @mav_type_gcs do
    # An autopilot off component 1 has no link counters: none lost.
    {_, received, lost} = Map.get(log.links, frame.sysid, {nil, 0, 0})

    update(log, frame, fn v ->
      armed = (hb.base_mode &&& @armed_flag) != 0
      autopilot = if ap == @mav_autopilot_px4, do: :px4, else: :ardupilot
      mode = Modes.name(autopilot, type, hb.custom_mode)
      v = %{v | type: type, autopilot: autopilot}
      v = if armed != v.armed, do: %{v | armed: armed, arming: [{ts, armed} | v.arming]}, else: v
      v = if mode != v.mode, do: %{v | mode: mode, modes: [{ts, mode} | v.modes]}, else: v
      %{v | link: [{ts, received, lost} | v.link]}
    end)
  end

  # ArduPilot reports 0, 0 until its position estimate has an origin (SITL
  # for its first seconds): no place, but its boot clock counts.
  defp message(%M.GlobalPositionInt{lat: 0, lon: 0} = p, ts, frame, log), do: boot_clock(log, frame.sysid, ts, p.time_boot_ms)

  defp message(%M.GlobalPositionInt{} = p, ts, frame, log) do
    log = boot_clock(log, frame.sysid, ts, p.time_boot_ms)
    update(log, frame, &%{&1 | positions: [{ts, p.lat, p.lon, p.relative_alt, p.vx, p.vy} | &1.positions]})
  end

  defp message(%M.HomePosition{} = h, ts, frame, log),
    do: update(log, frame, &%{&1 | homes: [{ts, {h.latitude, h.longitude, h.altitude}} | &1.homes]})

  defp message(%M.SysStatus{battery_remaining: pct}, ts, frame, log) when pct >= 0,
    do: update(log, frame, &%{&1 | battery: [{ts, pct} | &1.battery]})

  defp message(%M.MissionItemReached{seq: seq}, ts, frame, log),
    do: update(log, frame, &%{&1 | reached: [{ts, seq} | &1.reached]})

  defp message(%M.CameraImageCaptured{lat: lat, lon: lon}, ts, frame, log),
    do: update(log, frame, &%{&1 | photos: [{ts, lat, lon} | &1.photos]})

  defp message(%M.Statustext{severity: severity, text: text}, ts, frame, log),
    do: update(log, frame, &%{&1 | texts: [{ts, severity, clean_text(text)} | &1.texts]})

  # A ground station's upload: MISSION_COUNT opens it, MISSION_ITEM_INT fills
  # it (a retransmitted item replaces its first copy). The vehicle's own
  # items (a download to verify) are addressed to the ground station and so
  # land under its id, which is not a vehicle.
  defp message(%M.MissionCount{mission_type: 0, target_system: target, count: count}, ts, %Frame{sysid: from}, log) when target != from,
    do: update_id(log, target, &%{&1 | uploads: [%{at: ts, count: count, items: %{}} | &1.uploads]})

  defp message(%M.MissionItemInt{mission_type: 0, target_system: target} = item, _ts, %Frame{sysid: from}, log) when target != from do
    update_id(log, target, fn
      %{uploads: [upload | older]} = v ->
        %{v | uploads: [%{upload | items: Map.put(upload.items, item.seq, {item.command, item.x, item.y, item.z})} | older]}

      v ->
        v
    end)
  end

  # A fence or rally list uploaded: the latest one replaces the one before.
  defp message(%M.MissionCount{mission_type: type, target_system: target}, _ts, %Frame{sysid: from}, log) when type in [1, 2] and target != from,
    do: update_id(log, target, &Map.put(&1, list_key(type), %{}))

  defp message(%M.MissionItemInt{mission_type: type, target_system: target} = item, _ts, %Frame{sysid: from}, log) when type in [1, 2] and target != from,
    do: update_id(log, target, &Map.update!(&1, list_key(type), fn items -> Map.put(items, item.seq, {item.command, item.x, item.y, item.z, item.param1}) end))

  defp message(_other, _ts, _frame, log), do: log

  # A declared sensor's reading (any component), besides what the message says otherwise.
  defp sense(%m{name: name, value: value}, ts, frame, log) when m in [M.NamedValueFloat, M.NamedValueInt] and is_number(value) do
    if MapSet.member?(log.sensors.named, name), do: reading(log, frame, {:named_value, name}, ts, value), else: log
  end

  defp sense(%module{} = msg, ts, frame, %{sensors: %{fields: fields}} = log) when is_map_key(fields, module) do
    Enum.reduce(Map.fetch!(fields, module), log, fn field, log ->
      case Map.fetch!(msg, field) do
        value when is_number(value) -> reading(log, frame, {:message, module, field}, ts, value)
        _ -> log
      end
    end)
  end

  defp sense(_message, _ts, _frame, log), do: log

  defp reading(log, frame, source, ts, value), do: update(log, frame, &%{&1 | sensors: Map.update(&1.sensors, source, [{ts, value}], fn list -> [{ts, value} | list] end)})

  defp list_key(1), do: :fence
  defp list_key(2), do: :rally

  defp update(log, %Frame{sysid: id}, fun), do: update_id(log, id, fun)

  defp update_id(log, id, fun) do
    v = Map.get_lazy(log.vehicles, id, fn -> %Vehicle{id: id} end)
    %{log | vehicles: Map.put(log.vehicles, id, fun.(v))}
  end

  # Link quality from the autopilot's sequence numbers: each gap is frames lost
  # on the way. A number repeated or from up to half the ring behind is a
  # duplicate or a frame overtaken on the way: neither received nor lost.
  defp sequence(links, %Frame{compid: 1, sysid: id, seq: seq}) do
    case links do
      %{^id => {last, received, lost}} ->
        case band(seq - last, 0xFF) do
          step when step == 0 or step > 128 -> links
          step -> %{links | id => {seq, received + 1, lost + step - 1}}
        end

      _ ->
        Map.put(links, id, {seq, 1, 0})
    end
  end

  defp sequence(links, _frame), do: links

  # How fast the vehicles' clocks ran against the log's: the sum of steps of
  # their boot time over the steps of the log's time. A simulator sped up K
  # times runs K times faster than the wall clock that stamps the records.
  defp boot_clock(log, id, ts, boot_ms) do
    log =
      case log.boot_last do
        %{^id => {last_ts, last_boot}} when boot_ms > last_boot and boot_ms - last_boot < @max_boot_step_ms and ts > last_ts ->
          %{log | boot_ms: log.boot_ms + (boot_ms - last_boot), boot_real_us: log.boot_real_us + (ts - last_ts)}

        %{^id => {last_ts, last_boot}} when boot_ms + @restart_ms < last_boot ->
          new_run(log, last_ts)

        _ ->
          log
      end

    %{log | boot_last: Map.put(log.boot_last, id, {ts, boot_ms})}
  end

  # A boot clock started again after the whole log fell silent (since that
  # vehicle's previous frame, at `last_ts`): a new run began where the
  # silence ended, noted once for all its vehicles.
  defp new_run(%__MODULE__{silence: {start, _} = silence, starts: starts} = log, last_ts) when start > last_ts do
    if List.first(starts) == silence, do: log, else: %{log | starts: [silence | starts]}
  end

  defp new_run(log, _last_ts), do: log

  defp clean_text(text) when is_binary(text) do
    text = text |> :binary.split(<<0>>) |> hd()
    if String.valid?(text), do: text, else: inspect(text)
  end

  defp clean_text(text), do: inspect(text)

  # Keeps the vehicles (a ground station or a lone camera is not one) with
  # their lists oldest first.
  defp finish(log) do
    vehicles =
      for {id, v} <- log.vehicles, v.type != nil or v.positions != [], into: %{} do
        uploads = v.uploads |> Enum.reverse() |> Enum.reject(&(&1.items == %{}))

        {id,
         %{
           v
           | homes: Enum.reverse(v.homes),
             home: v.homes |> List.last() |> home(),
             positions: Enum.reverse(v.positions),
             arming: Enum.reverse(v.arming),
             modes: Enum.reverse(v.modes),
             battery: Enum.reverse(v.battery),
             link: Enum.reverse(v.link),
             uploads: uploads,
             reached: Enum.reverse(v.reached),
             photos: Enum.reverse(v.photos),
             texts: Enum.reverse(v.texts),
             sensors: Map.new(v.sensors, fn {source, list} -> {source, Enum.reverse(list)} end)
         }}
      end

    %{log | vehicles: vehicles, links: %{}, boot_last: %{}}
  end

  @doc false
  # The runs the log holds, oldest first: the stamps of the first and the
  # last record of each ([] for a log with no record).
  @spec runs(t()) :: [{integer(), integer()}]
  def runs(%__MODULE__{first_us: nil}), do: []

  def runs(%__MODULE__{} = log) do
    starts = Enum.reverse(log.starts)
    firsts = [log.first_us | Enum.map(starts, &elem(&1, 0))]
    lasts = Enum.map(starts, &elem(&1, 1)) ++ [log.last_us]
    Enum.zip(firsts, lasts)
  end

  @doc false
  # The log of its `n`th run (from 1) alone: what the vehicles recorded
  # from its first record to its last; a vehicle not heard then is left out.
  @spec select(t(), pos_integer()) :: t()
  def select(%__MODULE__{} = log, n) do
    case runs(log) do
      [_] ->
        log

      runs ->
        {first, last} = Enum.at(runs, n - 1)
        within = fn ts -> ts >= first and ts <= last end
        keep = fn list -> Enum.filter(list, &within.(elem(&1, 0))) end

        vehicles = for {id, v} <- log.vehicles, v = select_vehicle(v, first, within, keep), v.positions != [] or v.modes != [], into: %{}, do: {id, v}

        %{log | vehicles: vehicles, first_us: first, last_us: last, starts: []}
    end
  end

  defp select_vehicle(v, first, within, keep) do
    homes = keep.(v.homes)

    %{
      v
      | homes: homes,
        # A home not sent again in this run is the one it had before.
        home: home(List.first(homes) || v.homes |> Enum.filter(&(elem(&1, 0) < first)) |> List.last()),
        positions: keep.(v.positions),
        arming: keep.(v.arming),
        modes: keep.(v.modes),
        battery: keep.(v.battery),
        link: keep.(v.link),
        uploads: Enum.filter(v.uploads, &within.(&1.at)),
        reached: keep.(v.reached),
        photos: keep.(v.photos),
        texts: keep.(v.texts),
        sensors: Map.new(v.sensors, fn {source, list} -> {source, keep.(list)} end)
    }
  end

  defp home(nil), do: nil
  defp home({_ts, home}), do: home

  @doc false
  # A record's stamp (µs since the epoch) as the log's clock seconds: from
  # its first record, at the vehicles' rate (speedup/1).
  @spec clock(t()) :: (integer() -> float())
  def clock(%__MODULE__{first_us: first} = log) do
    k = speedup(log)
    fn ts -> (ts - first) * k / 1_000_000 end
  end

  @doc false
  # The vehicles' clock rate over the log's (1.0 when the log does not tell).
  @spec speedup(t()) :: float()
  def speedup(%__MODULE__{boot_ms: b, boot_real_us: r}) when b > 0 and r > 0, do: b * 1000 / r
  def speedup(_log), do: 1.0
end
