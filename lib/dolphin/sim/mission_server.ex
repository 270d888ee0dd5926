defmodule Dolphin.Sim.MissionServer do
  @moduledoc false
  # The vehicle side of the MAVLink mission protocol, as ArduCopter plays it
  # (see docs/ardupilot.md), as a pure state machine: `handle/4` takes one message
  # from a ground station and returns the replies; `timeout/3` runs the upload's
  # re-request timer, due at `deadline/1`.
  #
  # - Uploads are asked for item by item with MISSION_REQUEST (ArduPilot's
  #   choice), or MISSION_REQUEST_INT when `request_int: true`; MISSION_ITEM_INT
  #   and the float MISSION_ITEM are both accepted (the latter with ArduPilot's
  #   complaint). Only the item asked for is taken, and the next one asked for
  #   at once; any other draws INVALID_SEQUENCE and nothing else (the next
  #   request is the timer's). Asked again when a second passes without a
  #   request sent; OPERATION_CANCELLED after 8 s without an item taken
  #   (and, when the caller gives real time, 2 s of it, which above 4x is
  #   what decides: see below). A
  #   second MISSION_COUNT from the same ground station starts again; from
  #   another, DENIED while one is busy. More than `limit` items, NO_SPACE; an
  #   unknown command, UNSUPPORTED.
  # - While an upload is under way, downloads are DENIED, and a clear is
  #   accepted and ends the upload; when none is, an item draws
  #   MAV_MISSION_ERROR (so a ground station that resends the last item after a
  #   lost ACCEPTED learns the upload is over). A ground station's MISSION_ACK
  #   changes nothing: ArduCopter goes on with an upload after one.
  # - A cleared mission counts 0 items, not even home, until home is written
  #   again (at arming: `home_written/1`, or by an upload).
  # - A request for an item past the end draws MISSION_COUNT (ArduPilot
  #   "educates" the ground station) and INVALID_SEQUENCE.
  # - For the mission (type 0) item 0 is home: an uploaded item 0 is ignored and
  #   a downloaded item 0 is the current home (`home: false` keeps item 0 as
  #   sent, for test vehicles). Frames are normalised on the way back (the
  #   `_INT` frames read back as their float twins), as ArduPilot does.
  # - Fence (1) and rally (2) lists are kept as uploaded.
  # - A fault for tests, `gives_up: n`: the next n uploads are dropped at their
  #   last item, answered MAV_MISSION_ERROR and nothing stored — what a ground
  #   station sees of a vehicle whose patience ran out just before that item
  #   came, its OPERATION_CANCELLED lost.
  #
  # The 8 s are vehicle time. ArduPilot SITL's time stands still while its
  # host starves it; the simulator's runs on with the clock and catches up
  # after a pause, so at 25x a pause of this host of a third of a second
  # looked like 8 s of silence and ended the upload (a lossy-link run beside
  # busy loops lost five in a row). Given real time (`ctx.real`, `timeout/3`),
  # the upload also waits @upload_timeout_real_floor_ms of it: at 1x the 8 s
  # decide, as on ArduPilot.

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.MissionItems

  @rerequest_ms 1_000
  @upload_timeout_ms 8_000
  @upload_timeout_real_floor_ms 2_000

  # MAV_MISSION_RESULT values.
  @accepted 0
  @error 1
  @unsupported 3
  @no_space 4
  @invalid_sequence 13
  @denied 14
  @cancelled 15

  # Mission commands the simulated copter knows how to fly or perform.
  @supported [16, 17, 18, 19, 20, 21, 22, 93, 112, 113, 114, 115, 177, 178, 179, 181, 183, 186, 189, 201, 203, 205, 206, 2000, 2001, 5000, 5001, 5002, 5003, 5004]

  # ArduPilot reads every `_INT` frame back as the float frame it stands for.
  @normalised_frames %{5 => 0, 6 => 3, 11 => 10}

  defstruct lists: %{0 => [], 1 => [], 2 => []},
            upload: nil,
            request_int: false,
            gives_up: 0,
            home: true,
            home_stored: true,
            limit: 650

  @type t :: %__MODULE__{}
  @type peer :: {byte(), byte()}
  @type reply :: {:send, struct()} | {:text, 0..7, String.t()} | {:changed, 0..2}

  @spec new(keyword()) :: t()
  def new(opts \\ []),
    do: %__MODULE__{request_int: Keyword.get(opts, :request_int, false), limit: Keyword.get(opts, :limit, 650), home: Keyword.get(opts, :home, true), gives_up: Keyword.get(opts, :gives_up, 0)}

  @doc false
  @spec supported?(non_neg_integer()) :: boolean()
  def supported?(command), do: command in @supported

  @doc "The items of a list (for the mission: item 1 onwards, home not included)."
  @spec items(t(), 0..2) :: [struct()]
  def items(%__MODULE__{lists: lists}, type \\ 0), do: Map.get(lists, type, [])

  @doc """
  When the upload's re-request timer is due (vehicle ms), or nil. With real
  time given, the next re-request: the 8 s may have passed while the real
  floor has not.
  """
  @spec deadline(t()) :: integer() | nil
  def deadline(%__MODULE__{upload: nil}), do: nil
  def deadline(%__MODULE__{upload: %{received_real: real} = up}) when is_integer(real), do: up.requested + @rerequest_ms
  def deadline(%__MODULE__{upload: up}), do: min(up.requested + @rerequest_ms, up.received + @upload_timeout_ms)

  @doc """
  One message from the ground station `peer`. `home` is the item 0 to hand out
  on a download of the mission. Returns the new state and what to do.
  """
  @spec handle(t(), struct(), peer(), %{required(:now) => integer(), required(:home) => struct() | nil, optional(:real) => integer() | nil}) :: {t(), [reply()]}
  def handle(server, message, peer, ctx)

  def handle(%__MODULE__{upload: %{peer: other}} = s, %M.MissionCount{mission_type: type}, peer, _ctx) when other != peer,
    do: {s, [{:send, ack(peer, type, @denied)}]}

  def handle(%__MODULE__{} = s, %M.MissionCount{count: count, mission_type: type}, peer, ctx) do
    cond do
      type not in 0..2 ->
        {s, [{:send, ack(peer, type, @unsupported)}]}

      count > s.limit ->
        {%{s | upload: nil}, [{:send, ack(peer, type, @no_space)}, {:text, 3, "Only #{s.limit} items are supported"}]}

      count == 0 ->
        {%{s | upload: nil, lists: Map.put(s.lists, type, [])}, [{:send, ack(peer, type, @accepted)}, {:changed, type}]}

      true ->
        up = %{peer: peer, type: type, count: count, items: [], received: ctx.now, received_real: ctx[:real], requested: ctx.now}
        s = %{s | upload: up}
        {s, [request(s, 0)]}
    end
  end

  def handle(%__MODULE__{upload: %{peer: peer, type: type} = up} = s, %item_type{mission_type: type, seq: seq} = item, peer, ctx)
      when item_type in [M.MissionItemInt, M.MissionItem] do
    expected = length(up.items)
    complaint = if item_type == M.MissionItem, do: [{:text, 4, "GCS should send MISSION_ITEM_INT"}], else: []

    cond do
      seq != expected ->
        # The spec's answer to an unexpected item; ArduPilot's timer asks again.
        {s, [{:send, ack(peer, type, @invalid_sequence)}]}

      type == 0 and seq > 0 and not supported?(item.command) ->
        {%{s | upload: nil}, complaint ++ [{:send, ack(peer, type, @unsupported)}, {:text, 6, "Mission: unsupported command #{item.command}"}]}

      seq + 1 == up.count and s.gives_up > 0 ->
        {%{s | upload: nil, gives_up: s.gives_up - 1}, [{:send, ack(peer, type, @error)}]}

      seq + 1 == up.count ->
        list = Enum.reverse([MissionItems.to_int(item) | up.items])
        # Item 0 of the mission is home: accepted and ignored.
        list = if type == 0 and s.home, do: tl(list), else: list
        lists = Map.put(s.lists, type, list)
        s = %{s | home_stored: s.home_stored or type == 0}
        done = [{:send, ack(peer, type, @accepted)}, {:changed, type}] ++ if(type == 0, do: [{:text, 6, "Flight plan received"}], else: [])
        {%{s | upload: nil, lists: lists}, complaint ++ done}

      true ->
        s = %{s | upload: %{up | items: [MissionItems.to_int(item) | up.items], received: ctx.now, received_real: ctx[:real], requested: ctx.now}}
        {s, complaint ++ [request(s, seq + 1)]}
    end
  end

  # No upload under way (it ended, or never began): ArduPilot's answer to an
  # item (but a guided-mode target, current 2 or 3).
  def handle(%__MODULE__{upload: nil} = s, %item_type{mission_type: type, current: current}, peer, _ctx)
      when item_type in [M.MissionItemInt, M.MissionItem] and current not in [2, 3],
      do: {s, [{:send, ack(peer, type, @error)}]}

  # Downloads wait for the upload to end.
  def handle(%__MODULE__{upload: %{}} = s, %request{mission_type: type}, peer, _ctx) when request in [M.MissionRequestList, M.MissionRequestInt, M.MissionRequest],
    do: {s, [{:send, ack(peer, type, @denied)}]}

  def handle(%__MODULE__{} = s, %M.MissionRequestList{mission_type: type}, peer, ctx) do
    count = length(download_list(s, type, ctx.home))
    {s, [{:send, %M.MissionCount{target_system: elem(peer, 0), target_component: elem(peer, 1), count: count, mission_type: type}}]}
  end

  def handle(%__MODULE__{} = s, %request{seq: seq, mission_type: type}, peer, ctx) when request in [M.MissionRequestInt, M.MissionRequest] do
    list = download_list(s, type, ctx.home)

    case Enum.at(list, seq) do
      nil ->
        count = %M.MissionCount{target_system: elem(peer, 0), target_component: elem(peer, 1), count: length(list), mission_type: type}
        {s, [{:send, count}, {:send, ack(peer, type, @invalid_sequence)}]}

      item ->
        item = %{item | seq: seq, target_system: elem(peer, 0), target_component: elem(peer, 1), mission_type: type}
        {s, [{:send, if(request == M.MissionRequestInt, do: item, else: MissionItems.to_float(item))}]}
    end
  end

  # A clear ends an upload under way too. A cleared mission has no home item
  # either until home is written again (at arming, or by an upload).
  def handle(%__MODULE__{} = s, %M.MissionClearAll{mission_type: type}, peer, _ctx) when type in 0..2 do
    s = %{s | lists: Map.put(s.lists, type, []), upload: nil, home_stored: s.home_stored and type != 0}
    {s, [{:send, ack(peer, type, @accepted)}, {:changed, type}]}
  end

  def handle(%__MODULE__{} = s, %M.MissionClearAll{mission_type: type}, peer, _ctx), do: {s, [{:send, ack(peer, type, @unsupported)}]}

  # Anything else, MISSION_ACK included: ArduCopter SITL 4.7 goes on with an
  # upload under way after a ground station's MISSION_ACK, even
  # OPERATION_CANCELLED. Ending it there let the late ACK of the download
  # before an upload cancel that upload.
  def handle(%__MODULE__{} = s, _other, _peer, _ctx), do: {s, []}

  @doc "Home is written to the mission's item 0 (ArduCopter does so when it arms)."
  @spec home_written(t()) :: t()
  def home_written(%__MODULE__{} = s), do: %{s | home_stored: true}

  @doc """
  The re-request timer: ask again after a second, give up after 8 s without
  an item — and, when `real` (monotonic ms) is given here and was in the
  ctx of the item, after #{@upload_timeout_real_floor_ms} ms of real time too.
  """
  @spec timeout(t(), integer(), integer() | nil) :: {t(), [reply()]}
  def timeout(server, now, real \\ nil)
  def timeout(%__MODULE__{upload: nil} = s, _now, _real), do: {s, []}

  def timeout(%__MODULE__{upload: up} = s, now, real) do
    cond do
      now - up.received > @upload_timeout_ms and patience_spent_in_real_time?(up, real) ->
        {%{s | upload: nil}, [{:send, ack(up.peer, up.type, @cancelled)}, {:text, 3, "Mission upload timeout"}]}

      now - up.requested >= @rerequest_ms ->
        s = %{s | upload: %{up | requested: now}}
        {s, [request(s, length(up.items))]}

      true ->
        {s, []}
    end
  end

  defp patience_spent_in_real_time?(%{received_real: since}, real) when is_integer(since) and is_integer(real), do: real - since > @upload_timeout_real_floor_ms
  defp patience_spent_in_real_time?(_up, _real), do: true

  defp download_list(%{home: true, home_stored: false}, 0, _home), do: []
  defp download_list(%{home: true} = s, 0, home), do: [home || %M.MissionItemInt{command: 16, frame: 0}] ++ Enum.map(items(s, 0), &normalise/1)
  defp download_list(s, type, _home), do: items(s, type)

  defp normalise(item), do: %{item | frame: Map.get(@normalised_frames, item.frame, item.frame)}

  defp request(%{upload: up, request_int: int?}, seq) do
    {sysid, compid} = up.peer
    module = if int?, do: M.MissionRequestInt, else: M.MissionRequest
    {:send, struct(module, target_system: sysid, target_component: compid, seq: seq, mission_type: up.type)}
  end

  defp ack({sysid, compid}, type, result), do: %M.MissionAck{target_system: sysid, target_component: compid, type: result, mission_type: type}
end
