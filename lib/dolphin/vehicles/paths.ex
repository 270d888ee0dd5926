defmodule Dolphin.Vehicles.Paths do
  @moduledoc """
  The paths to one vehicle — one per link it is heard on, and per address
  on a `udpin` link (two radios, a radio and a relay) — kept by pure
  functions that the vehicle's process drives: which frames are new, how
  good each path is, and which one to send on.

  Each path has a `via` (see `t:via/0`), the clock time it was last heard,
  the frames received on it, its loss from the sequence numbers seen on it
  (per component), its round trip and round-trip loss from the TIMESYNCs sent
  on it (a `Dolphin.Vehicles.LinkQuality` per path; an answer counts only for
  the path whose request it names, by `ts1`, and only when it comes back on
  that path), and a state: `:active` (the path in use), `:standby` (heard, not
  in use) or `:silent`.

  ## De-duplication

  The same frame heard on two paths is one frame: `heard/5` says `:fresh` the
  first time and `:duplicate` for a copy of it on another path: same
  component, same sequence number, same bytes, within a second of real time
  and fewer than 128 new frames of that component ago. Copies still count in
  their own path's figures. A frame heard again on the *same* path is always
  fresh (a vehicle heard on one link behaves as if there were no
  de-duplication at all): the 8-bit sequence number wraps, a vehicle that
  reboots starts again at 0, and a network may duplicate a datagram — none of
  these may eat a frame. The one frame that could be misjudged (a vehicle that
  rebooted within the second, whose new frame has the bytes of an old one
  heard only on the other path) is then taken from the other path's copy.

  ## The path in use

  A path is silent once it has been quiet for 1.5 s of clock time and at
  least 200 ms of real time (at a high speed-up 1.5 s of clock time is a few
  tens of real milliseconds, less than a loaded host may hold the ground
  station up). The path in use is, among the paths not silent, the one with
  the lowest loss (round-trip loss once measured, else the loss towards the
  ground station, else none), then the lowest round trip; another path takes
  over from one still heard only when it has been clearly better for 2 s of
  real time (5 points less loss and two more of the latest 20 TIMESYNCs
  answered; or as lossy, and a round trip under two thirds and 20 ms less),
  so that two equal radios whose figures wobble do not take turns. When
  every path is silent the path in use stays (the vehicle, or this host, is
  silent: no path is better than another).

      iex> alias Dolphin.Vehicles.Paths
      iex> p = Paths.new("radio-a", 0, 0)
      iex> Paths.in_use(p)
      "radio-a"

  ## Another vehicle with the same system id

  Most vehicles leave the factory as system id 1, so the same system id on
  another link, or from another address of a `udpin` link, may be another
  vehicle rather than this one heard again. A path is therefore *pending*
  from its first frame until it is identified: its frames count in its own
  figures but are not the vehicle's (`heard/5` says `:unidentified`), and it
  is never the path in use.

  The first path a vehicle is heard on is its own: it is never pending, and
  the unique id its autopilot reports (AUTOPILOT_VERSION,
  `Dolphin.Vehicles.State.unique_id/1`) is the vehicle's, kept for as long
  as the vehicle is (`uid/1`; a restarted process is given it back with
  `identified/3`). `identity_asks/3` names the paths to ask for their
  autopilot's unique id — each pending path, at most 5 times, and the path
  the vehicle was discovered on until the vehicle's is known (asked anew
  when a new path is pending; the vehicle's id is its autopilot's) —, a
  second of clock time apart at least and, in real time, half a second
  after the first ask, doubling after each up to 8 s (an
  autopilot on a loaded host answers late; at a speed-up it still needs its
  time; two vehicles taken for one are worse than a path decided late): a
  pending path that never answers is given up 15.5 s of real time after
  its first ask at the soonest;
  `identified/3` records what a path's autopilot answered; `settle/3` decides:

    * the vehicle's and the path's ids known, non-zero and different:
      another vehicle. The path is `:refused` for good; its frames are never
      the vehicle's, it is sent nothing (the vehicle's process then gives
      the path to that other vehicle, `Dolphin.Vehicles.Id`);
    * the same id: the same vehicle;
    * no id to compare (an autopilot that reports 0; one that does not
      answer 5 times; the vehicle's own not known while the path it was
      discovered on has been quiet for 15 s of clock time and 10 s of real time): taken to be
      the same vehicle, as a
      redundant radio is — two vehicles that cannot be told apart are
      not.
  """

  alias Dolphin.MAVLink.Ardupilotmega.Timesync
  alias Dolphin.MAVLink.Frame
  alias Dolphin.Vehicles.LinkQuality

  @silence_ms 1_500
  @silence_real_floor_ms 200
  @dedup_window_real_ms 1_000
  # New frames of a component after which a remembered one no longer matches:
  # half the sequence space, so that a wrap never matches an old frame.
  @dedup_depth 128
  @loss_margin 0.05
  @more_lost 2
  @rtt_ratio 1.5
  @rtt_margin_ms 20
  # How long (real ms) another path must stay clearly better before it takes over.
  @better_for_real_ms 2_000
  # Asking a path for its autopilot's uid: this many times, this often (clock
  # ms, and at least the real floor, doubled after each ask), before taking
  # it as unidentifiable.
  @identity_asks 5
  @identity_asks_after 10
  @identity_ask_every_ms 1_000
  @identity_ask_real_floor_ms 500
  # The path the vehicle was discovered on quiet this long (clock, and real)
  # before a pending path is decided without the vehicle's own id.
  @identity_silence_ms 15_000
  @identity_silence_real_ms 10_000

  defstruct paths: %{}, in_use: nil, own: nil, recent: %{}, fresh: %{}, challenger: nil, uid: nil

  @typedoc """
  A path's name: what the link gives with each frame (a
  `t:Dolphin.Link.Connection.via/0`: the link's name and, for a `udpin` link,
  the address the vehicle sends from); any term in tests.
  """
  @type via :: term()
  @type path_state :: :active | :standby | :silent
  @typedoc "Whether a path is the vehicle's (see \"Another vehicle with the same system id\")."
  @type identity :: :same | :pending | :refused
  @type t :: %__MODULE__{
          paths: %{via() => map()},
          in_use: via() | nil,
          own: via() | nil,
          recent: %{byte() => %{byte() => {integer(), MapSet.t(), integer(), non_neg_integer()}}},
          fresh: %{byte() => non_neg_integer()},
          challenger: nil | {via(), integer()},
          uid: non_neg_integer() | nil
        }

  @typedoc "A path as `list/1` shows it."
  @type summary :: %{
          via: via(),
          state: path_state(),
          loss: float() | nil,
          rtt_ms: non_neg_integer() | nil,
          last_heard_ms: integer(),
          frames: non_neg_integer(),
          in_use?: boolean(),
          identity: identity(),
          uid: non_neg_integer() | nil
        }

  @doc "The paths of a vehicle first heard on `via` at `now_ms` (clock) and `real_ms` (real): that path in use."
  @spec new(via(), integer(), integer()) :: t()
  # `own`: the path the vehicle was discovered on, whose autopilot's id is the vehicle's.
  def new(via, now_ms, real_ms), do: %__MODULE__{paths: %{via => path(via, now_ms, real_ms, :active, :same)}, in_use: via, own: via}

  defp path(via, now_ms, real_ms, state, identity) do
    %{
      via: via,
      state: state,
      identity: identity,
      uid: nil,
      asks: 0,
      asked: nil,
      last_heard_ms: now_ms,
      last_heard_real_ms: real_ms,
      frames: 0,
      lost: 0,
      seqs: %{},
      quality: LinkQuality.new()
    }
  end

  @doc "The path in use."
  @spec in_use(t()) :: via()
  def in_use(%__MODULE__{in_use: via}), do: via

  @doc "The `Dolphin.Vehicles.LinkQuality` of the path in use."
  @spec quality(t()) :: LinkQuality.t()
  def quality(%__MODULE__{paths: paths, in_use: via}), do: paths[via].quality

  @doc """
  A frame heard on `via` at `now_ms` (clock) and `real_ms` (real): counted in
  that path's figures (a TIMESYNC answer to this path's request gives a round
  trip), and judged `:fresh` or `:duplicate` (see "De-duplication"), or
  `:unidentified` on a path not known to be this vehicle's (see "Another
  vehicle with the same system id": a new path is pending).
  """
  @spec heard(t(), via(), Frame.t(), integer(), integer()) :: {:fresh | :duplicate | :unidentified, t()}
  def heard(%__MODULE__{} = p, via, %Frame{} = frame, now_ms, real_ms) do
    p = if Map.has_key?(p.paths, via), do: p, else: new_path(p, via, now_ms, real_ms)
    path = p.paths[via] |> count(frame, now_ms, real_ms) |> timesync_answer(frame.message, real_ms)
    path = if path.state == :silent, do: %{path | state: :standby}, else: path
    p = %{p | paths: Map.put(p.paths, via, path)}

    # Not this vehicle's (yet): nothing of it may mark a frame of the
    # vehicle's own paths as a copy.
    if path.identity == :same, do: dedup(p, via, frame, real_ms), else: {:unidentified, p}
  end

  # A pending path; while the vehicle's own unique id is not known, the path
  # it was discovered on is asked again from now on.
  defp new_path(p, via, now_ms, real_ms) do
    paths = Map.put(p.paths, via, path(via, now_ms, real_ms, :standby, :pending))
    paths = if p.uid == nil, do: Map.update!(paths, own_via(p), &%{&1 | asks: 0, asked: nil}), else: paths
    %{p | paths: paths}
  end

  @doc """
  Records the unique id (`Dolphin.Vehicles.State.unique_id/1`, 0 for none)
  that the autopilot heard on `via` reported; on a path of the vehicle's own
  it is the vehicle's.
  """
  @spec identified(t(), via(), non_neg_integer()) :: t()
  def identified(%__MODULE__{} = p, via, uid) do
    own? = p.uid == nil and via == own_via(p)

    case p.paths do
      # The path the vehicle was discovered on: the vehicle's own id, unless
      # known already. Paths taken for the vehicle's that reported another
      # id are decided again.
      %{^via => %{identity: :same} = path} when own? ->
        recheck(%{p | paths: Map.put(p.paths, via, %{path | uid: uid}), uid: uid})

      %{^via => path} ->
        recheck(%{p | paths: Map.put(p.paths, via, %{path | uid: uid})})

      _ ->
        p
    end
  end

  # A path taken for the vehicle's for want of an answer (on a host too
  # loaded to answer in time) whose autopilot then reports an id other than
  # the vehicle's is another vehicle's after all: pending again, `settle/3`
  # refuses it, and `judge/3` moves off it if it was in use.
  defp recheck(%__MODULE__{uid: own} = p) when is_integer(own) and own != 0 do
    paths =
      Map.new(p.paths, fn
        {via, %{identity: :same, uid: uid} = path} when is_integer(uid) and uid != 0 and uid != own -> {via, %{path | identity: :pending}}
        other -> other
      end)

    %{p | paths: paths}
  end

  defp recheck(p), do: p

  # The path the vehicle was discovered on (its autopilot's id is the
  # vehicle's), or the one in use once that one is forgotten.
  defp own_via(%__MODULE__{own: own, paths: paths, in_use: in_use}), do: if(is_map_key(paths, own), do: own, else: in_use)

  @doc "The vehicle's unique id, as the autopilot on its own paths reported it (nil until then)."
  @spec uid(t()) :: non_neg_integer() | nil
  def uid(%__MODULE__{uid: uid}), do: uid

  @doc "Whether the vehicle has been heard on more than one path."
  @spec several?(t()) :: boolean()
  def several?(%__MODULE__{paths: paths}), do: map_size(paths) > 1

  @doc """
  The paths to ask now (at `now_ms` clock, `real_ms` real) for their
  autopilot's unique id, counted as asked: the pending ones whose uid is not
  known, and the path in use while a path is pending and its own uid is not
  known (see "Another vehicle with the same system id").
  """
  @spec identity_asks(t(), integer(), integer()) :: {[via()], t()}
  def identity_asks(%__MODULE__{} = p, now_ms, real_ms) do
    pending = for {via, %{identity: :pending, uid: nil} = path} <- p.paths, ask_due?(path, now_ms, real_ms), do: via

    # Paths taken for the vehicle's for want of an answer are asked on, 8 s
    # apart, 10 times more (a host loaded for a minute): an answer with
    # another id makes them another vehicle's (identified/3).
    unsure =
      for {via, %{identity: :same, uid: nil, asks: asks} = path} <- p.paths,
          via != own_via(p),
          asks >= @identity_asks and asks < @identity_asks + @identity_asks_after,
          waited?(path, now_ms, real_ms),
          do: via

    own = p.paths[own_via(p)]
    # The vehicle's own id: 5 times, and for as long as a path waits for it.
    waiting? = Enum.any?(p.paths, fn {_, path} -> path.identity == :pending end)
    asks = Enum.sort(pending ++ unsure) ++ if(p.uid == nil and (ask_due?(own, now_ms, real_ms) or (waiting? and waited?(own, now_ms, real_ms))), do: [own.via], else: [])

    paths = Enum.reduce(asks, p.paths, fn via, paths -> Map.update!(paths, via, &%{&1 | asks: &1.asks + 1, asked: {now_ms, real_ms}}) end)
    {asks, %{p | paths: paths}}
  end

  defp ask_due?(%{asks: 0}, _now_ms, _real_ms), do: true
  defp ask_due?(%{asks: asks}, _now_ms, _real_ms) when asks >= @identity_asks, do: false
  defp ask_due?(path, now_ms, real_ms), do: waited?(path, now_ms, real_ms)

  defp waited?(%{asked: {at, real_at}, asks: asks}, now_ms, real_ms),
    do: now_ms - at >= @identity_ask_every_ms and real_ms - real_at >= @identity_ask_real_floor_ms * Integer.pow(2, min(max(asks - 1, 0), @identity_asks - 1))

  # Asked as often as it is asked, and no answer in the last wait.
  defp gave_up?(%{uid: nil, asks: asks} = path, now_ms, real_ms), do: asks >= @identity_asks and waited?(path, now_ms, real_ms)
  defp gave_up?(_path, _now_ms, _real_ms), do: false

  @doc """
  Decides the pending paths that can be decided at `now_ms` (clock) and
  `real_ms` (real) (see "Another vehicle with the same system id"): the
  paths, and `{via, :same | :unidentifiable | {:refused, uid, vehicle_uid}}`
  for each path decided (`:unidentifiable`: taken as the same vehicle for
  want of uids to compare).
  """
  @spec settle(t(), integer(), integer()) :: {t(), [{via(), :same | :unidentifiable | {:refused, non_neg_integer(), non_neg_integer()}}]}
  def settle(%__MODULE__{} = p, now_ms, real_ms) do
    # The vehicle's id cannot come: its own path has gone quiet. (Heard
    # but not answering — a lossy link, an autopilot too busy — it is asked
    # again: a pending path that answered waits for it, a path that did not
    # is given up on by itself.)
    own = p.paths[own_via(p)]
    own_unknowable? = p.uid == nil and gone_quiet?(own, now_ms, real_ms)

    decisions =
      for {via, %{identity: :pending} = path} <- Enum.sort(p.paths),
          decision = decide(path.uid, p.uid, own_unknowable? or gave_up?(path, now_ms, real_ms)),
          decision != nil,
          do: {via, decision}

    paths =
      Enum.reduce(decisions, p.paths, fn {via, decision}, paths ->
        Map.update!(paths, via, &%{&1 | identity: if(match?({:refused, _, _}, decision), do: :refused, else: :same)})
      end)

    {%{p | paths: paths}, decisions}
  end

  # A pending path's id against the vehicle's; `over?`: no more to wait for.
  defp decide(0, _own, _over?), do: :unidentifiable
  defp decide(uid, 0, _over?) when is_integer(uid), do: :unidentifiable
  defp decide(uid, uid, _over?) when is_integer(uid), do: :same
  defp decide(uid, own, _over?) when is_integer(uid) and is_integer(own), do: {:refused, uid, own}
  defp decide(_uid, _own, true), do: :unidentifiable
  defp decide(_uid, _own, false), do: nil

  # Quiet long enough for its autopilot's id not to come: longer than a path
  # is silent, as a vehicle heard only by its 1 Hz heartbeat (before it is
  # asked for telemetry) on a loaded host is at times; a vehicle rebooting
  # onto a new address is quiet far longer than this before it is heard there.
  defp gone_quiet?(path, now_ms, real_ms), do: now_ms - path.last_heard_ms > @identity_silence_ms and real_ms - path.last_heard_real_ms > @identity_silence_real_ms

  defp silent?(path, now_ms, real_ms), do: now_ms - path.last_heard_ms > @silence_ms and real_ms - path.last_heard_real_ms > @silence_real_floor_ms

  # Sequence numbers are per component; a gap on this path is frames this path lost.
  defp count(path, %Frame{compid: compid, seq: seq}, now_ms, real_ms) do
    lost =
      case Map.fetch(path.seqs, compid) do
        {:ok, last} -> rem(seq - last - 1 + 256, 256)
        :error -> 0
      end

    # A jump of more than half the sequence space is a restart or a reordering, not a loss.
    lost = if lost > 128, do: 0, else: lost

    %{
      path
      | frames: path.frames + 1,
        lost: path.lost + lost,
        seqs: Map.put(path.seqs, compid, seq),
        last_heard_ms: now_ms,
        last_heard_real_ms: real_ms,
        quality: LinkQuality.frames(path.quality, 1, lost)
    }
  end

  # An answer to a TIMESYNC of ours (tc1 0 is the vehicle's own request): only
  # this path's pending requests can match it.
  defp timesync_answer(path, %Timesync{tc1: tc1, ts1: ts1}, real_ms) when tc1 != 0,
    do: %{path | quality: LinkQuality.reply(path.quality, ts1, real_ms)}

  defp timesync_answer(path, _message, _real_ms), do: path

  defp dedup(p, via, %Frame{compid: compid, seq: seq, raw: raw}, real_ms) do
    hash = :erlang.phash2(raw)
    n = Map.get(p.fresh, compid, 0)
    seen = Map.get(p.recent, compid, %{})

    case seen do
      %{^seq => {^hash, vias, at, k}} when real_ms - at <= @dedup_window_real_ms and n - k < @dedup_depth ->
        if MapSet.member?(vias, via) do
          fresh(p, via, compid, seq, hash, real_ms, n, seen)
        else
          {:duplicate, %{p | recent: Map.put(p.recent, compid, Map.put(seen, seq, {hash, MapSet.put(vias, via), at, k}))}}
        end

      _ ->
        fresh(p, via, compid, seq, hash, real_ms, n, seen)
    end
  end

  defp fresh(p, via, compid, seq, hash, real_ms, n, seen) do
    seen = Map.put(seen, seq, {hash, MapSet.new([via]), real_ms, n + 1})
    {:fresh, %{p | recent: Map.put(p.recent, compid, seen), fresh: Map.put(p.fresh, compid, n + 1)}}
  end

  @doc """
  TIMESYNC requests, one per path, stamped `ts1`, `ts1 + 1`, ...: the
  `{via, ts1}` to send, and the paths waiting for their answers (sent at
  `real_ms`).
  """
  @spec timesync(t(), integer(), integer()) :: {[{via(), integer()}], t()}
  def timesync(%__MODULE__{} = p, ts1, real_ms) do
    # Another vehicle's path is sent nothing.
    requests = for({via, path} <- p.paths, path.identity != :refused, do: via) |> Enum.sort() |> Enum.with_index(ts1)

    paths =
      Enum.reduce(requests, p.paths, fn {via, stamp}, paths ->
        Map.update!(paths, via, fn path -> %{path | quality: LinkQuality.request(path.quality, stamp, real_ms)} end)
      end)

    {requests, %{p | paths: paths}}
  end

  @doc """
  Measures every path at `real_ms` (`Dolphin.Vehicles.LinkQuality.measure/3`):
  a TIMESYNC unanswered for `stale_ms`, or four of the path's round trips if
  longer, is lost.
  """
  @spec measure(t(), integer(), pos_integer()) :: t()
  def measure(%__MODULE__{} = p, real_ms, stale_ms) do
    paths =
      Map.new(p.paths, fn {via, path} ->
        stale = max(stale_ms, 4 * (path.quality.rtt_ms || 0))
        {via, %{path | quality: LinkQuality.measure(path.quality, real_ms, stale)}}
      end)

    %{p | paths: paths}
  end

  @doc """
  Judges the paths at `now_ms` (clock) and `real_ms` (real): which are
  silent, and which to use (see "The path in use"). Returns the paths and,
  when the path in use changed, `{from, to, reason}` with reason `:silent`
  (the path in use went silent), `:another_vehicle` (it turned out to be
  another vehicle's) or `:better`.
  """
  @spec judge(t(), integer(), integer()) :: {t(), nil | {via(), via(), :silent | :another_vehicle | :better}}
  def judge(%__MODULE__{} = p, now_ms, real_ms) do
    paths = Map.new(p.paths, fn {via, path} -> {via, %{path | state: if(silent?(path, now_ms, real_ms), do: :silent, else: path.state)}} end)

    # Only the vehicle's own paths may be used.
    heard = paths |> Map.values() |> Enum.reject(&(&1.state == :silent or &1.identity != :same)) |> Enum.sort_by(&{score(&1), &1.via})
    current = paths[p.in_use]

    {in_use, reason, challenger} =
      cond do
        heard == [] -> {p.in_use, nil, nil}
        current.identity != :same -> {hd(heard).via, :another_vehicle, nil}
        current.state == :silent -> {hd(heard).via, :silent, nil}
        true -> challenge(current, Enum.reject(heard, &(&1.via == current.via)), p.challenger, real_ms)
      end

    paths =
      Map.new(paths, fn
        {^in_use, path} -> {in_use, %{path | state: if(path.state == :silent, do: :silent, else: :active)}}
        {via, %{state: :silent} = path} -> {via, path}
        {via, path} -> {via, %{path | state: :standby}}
      end)

    change = if in_use != p.in_use, do: {p.in_use, in_use, reason}
    {%{p | paths: paths, in_use: in_use, challenger: challenger}, change}
  end

  # The best other path, once it has been clearly better for long enough.
  defp challenge(current, [], _challenger, _real_ms), do: {current.via, nil, nil}

  defp challenge(current, [best | _], challenger, real_ms) do
    case {better?(best, current), challenger} do
      {false, _} -> {current.via, nil, nil}
      {true, {via, since}} when via == best.via and real_ms - since >= @better_for_real_ms -> {best.via, :better, nil}
      {true, {via, since}} when via == best.via -> {current.via, nil, {via, since}}
      {true, _} -> {current.via, nil, {best.via, real_ms}}
    end
  end

  # Hysteresis: clearly less lossy, or as lossy and clearly quicker.
  defp better?(a, b) do
    {la, lb} = {loss(a), loss(b)}
    {ra, rb} = {a.quality.rtt_ms, b.quality.rtt_ms}

    (la + @loss_margin < lb and more_lost(b, a) >= @more_lost) or
      (abs(la - lb) <= @loss_margin and is_number(ra) and is_number(rb) and ra * @rtt_ratio + @rtt_margin_ms < rb)
  end

  # How many more of its latest TIMESYNCs one path lost than the other: a
  # share of a few outcomes (the first ones, one unanswered during start-up)
  # is no evidence. Without round-trip figures, the loss towards the ground
  # station (from thousands of frames) speaks for itself.
  defp more_lost(%{quality: %{loss_rt: nil}}, _), do: @more_lost
  defp more_lost(_, %{quality: %{loss_rt: nil}}), do: @more_lost
  defp more_lost(b, a), do: unanswered(b) - unanswered(a)

  defp unanswered(%{quality: q}), do: Enum.count(q.outcomes, &(not &1))

  # Lowest loss first, then lowest round trip (unknown last).
  defp score(path), do: {loss(path), path.quality.rtt_ms || :unknown}

  defp loss(%{quality: q}), do: q.loss_rt || q.loss_in || 0.0

  @doc """
  A path's name in words: the link's name (its endpoint string unless it
  was given another), and the address a `udpin` link hears the vehicle from.

      iex> Dolphin.Vehicles.Paths.via_text({"udpin:0.0.0.0:14550", {{10, 0, 0, 7}, 14_555}})
      "udpin:0.0.0.0:14550 from 10.0.0.7:14555"
      iex> Dolphin.Vehicles.Paths.via_text({"tcp:127.0.0.1:5760", nil})
      "tcp:127.0.0.1:5760"
      iex> Dolphin.Vehicles.Paths.via_text({:radio, 2})
      "{:radio, 2}"
  """
  @spec via_text(via()) :: String.t()
  def via_text({name, nil}), do: via_text(name)
  def via_text({name, {ip, port}}) when is_tuple(ip) and is_integer(port), do: "#{via_text(name)} from #{:inet.ntoa(ip)}:#{port}"
  def via_text(via) when is_binary(via), do: via
  def via_text(via), do: inspect(via)

  @doc """
  Forgets the paths not heard for `after_ms` of clock time at `now_ms` whose
  link has heard the vehicle since from another address (a vehicle that
  restarted, a new NAT mapping: the old address is gone for good). A silent
  path of a link that has not heard the vehicle since stays, shown silent:
  that radio may come back.
  """
  @spec forget_silent(t(), integer(), pos_integer()) :: t()
  def forget_silent(%__MODULE__{} = p, now_ms, after_ms) do
    paths = Map.reject(p.paths, fn {via, path} -> via != p.in_use and now_ms - path.last_heard_ms > after_ms and replaced?(p.paths, via, path) end)
    %{p | paths: paths}
  end

  defp replaced?(paths, {link, _address} = via, path),
    do: Enum.any?(paths, fn {other, o} -> match?({^link, _}, other) and other != via and o.last_heard_ms > path.last_heard_ms end)

  defp replaced?(_paths, _via, _path), do: false

  @doc "The paths, the one in use first, then by name."
  @spec list(t()) :: [summary()]
  def list(%__MODULE__{} = p) do
    p.paths
    |> Map.values()
    |> Enum.sort_by(&{&1.via != p.in_use, &1.via})
    |> Enum.map(fn path ->
      %{
        via: path.via,
        state: path.state,
        loss: path.quality.loss_in,
        rtt_ms: path.quality.rtt_ms,
        last_heard_ms: path.last_heard_ms,
        frames: path.frames,
        in_use?: path.via == p.in_use,
        identity: path.identity,
        uid: path.uid
      }
    end)
  end
end
