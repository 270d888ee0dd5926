defmodule Dolphin.Vehicles.MissionProtocol do
  @moduledoc """
  The MAVLink mission protocol for one transfer with one vehicle, as a
  `:gen_statem` started by the vehicle's process (which routes the vehicle's
  mission messages to it). Works for the mission, fence and rally lists.

  It is written for bad radio links: frames are lost, duplicated and
  reordered both ways, and answers that belong to an earlier transaction
  arrive late. What it relies on is what ArduPilot's mission protocol
  (`MissionItemProtocol.cpp`, checked against ArduCopter SITL) guarantees:

  - after MISSION_COUNT it asks for item 0, and after accepting item `k` it
    asks for `k + 1` at once (sometimes twice), else again every second;
  - it accepts only the item it expects: any other draws `INVALID_SEQUENCE`
    and is dropped, so the items it holds are always the ones sent for their
    positions, in order;
  - the last item draws `ACCEPTED`, sent once; an item that arrives when no
    upload is under way draws `MAV_MISSION_ERROR`;
  - 8 s without an item it wanted ends its upload with `OPERATION_CANCELLED`;
  - a repeated MISSION_COUNT from the same ground station restarts the upload;
  - while not receiving, it answers a request for any item of its list.

  **Upload.** `{:count, _}` sends MISSION_COUNT until the vehicle asks for
  item 0 (a request for another item then is a late one of an earlier
  transaction). In `:sending`, the vehicle's requests tell how far it has
  come (`base`: every item before it is accepted). With *sending ahead*
  (ArduPilot, unless `send_ahead: false`), the items from `base` on are kept
  in flight up to a window of `:window` items (default 8) without waiting to
  be asked; a loss shows as `INVALID_SEQUENCE` for the items after the gap,
  or as no progress for a retransmission timeout, and both resend from
  `base` (go-back-N). Without it (PX4 and others, whose mission protocol
  wants items asked for one by one), an item is sent when asked for, and
  again after a timeout. A request repeated within a timeout of the first is
  a duplicate and is not answered twice. `ACCEPTED` ends it once every item
  has gone out at least once (so a stale ACCEPTED of an earlier transfer
  never makes a wrong mission look accepted); refusals (`NO_SPACE`,
  `UNSUPPORTED`, ...) end it with that result. `DENIED` to MISSION_COUNT
  (another ground station's upload under way, or a late answer to a
  download's request) is asked again at every timeout, and is the result
  only when the exchange is given up.

  If the vehicle cancels, or stops answering after it had answered, the
  transaction starts again with MISSION_COUNT, up to `:restarts` times
  (default 4). If every item went out and the vehicle answers the last one
  with `MAV_MISSION_ERROR` (no upload under way: its ACCEPTED was lost, or it
  gave up) within half its patience (4 s of clock time) of its last request,
  the result is `{:error, %MissionError{result: :unconfirmed}}`: only
  reading the mission back says whether it holds it (a mission task does,
  and uploads again if it does not). Later than that, it may well have
  given up: the transaction starts again.

  **Download** (`:download`): MISSION_REQUEST_LIST until MISSION_COUNT, then
  MISSION_REQUEST_INT for the missing items, a window of them at a time for
  ArduPilot (one at a time for others), re-asked after a timeout; then
  MISSION_ACK. Acks during a download answer nothing of it (they are late
  ones of the upload before it) except `DENIED` (the vehicle is busy with an
  upload: asked again later) and `UNSUPPORTED`.

  **Clear** (`:clear`): MISSION_CLEAR_ALL until MISSION_ACK (ArduCopter
  refuses with `MAV_MISSION_ERROR` while its mission runs in AUTO).

  **Timers and budgets.** Every retransmission timeout derives from the
  link's round trip: `:rtt_ms` (the vehicle's measured one, if known) and the
  samples this transfer takes (an answer to something sent once: Karn's rule):
  twice their 80th percentile (`Dolphin.Vehicles.Retry.timeout/3`), never under `Dolphin.Clock`'s
  retry floor nor over a second of clock time (when the vehicle asks again
  itself), doubled on every timeout in a row (up to 8×, within that second).
  Before any sample the timeout is a second of clock time. An exchange is given up after a number of
  timeouts in a row that grows with the loss (`Dolphin.Vehicles.Retry.attempts/1`
  of `:loss`, the link's round-trip loss if known, or what this transfer sees) — and never before 8 s of
  clock time without progress, the vehicle's own patience, nor before 5 s of real time
  (`Dolphin.Vehicles.Retry.patience_real_ms/2`: a fading radio or a stalled host) — or after exactly
  `:attempts` timeouts when given. `:total_timeout_ms`, when given, bounds
  the whole transfer.

  It is one state machine over one transfer (upload, download and clear
  share their timers, budgets, restarts and endings), kept in one module so
  that every transition can be read beside the others.

  The result goes to the caller: `:ok`, `{:ok, items}` (download), or
  `{:error, %Dolphin.MissionError{}}`; progress, if asked for, as
  `{:mission_progress, operation, done, total}` (items sent or received), and
  at the end `{:mission_done, operation, %{retransmissions: n, transactions: t}}`
  (items, requests and MISSION_COUNTs sent again; transactions begun).
  """

  @behaviour :gen_statem

  alias Dolphin.{Clock, MissionError}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.MissionItems
  alias Dolphin.Vehicles.Retry

  @types %{mission: 0, fence: 1, rally: 2}

  # MAV_MISSION_RESULT values this protocol tells apart.
  @accepted 0
  @error 1
  @unsupported 3
  @invalid_sequence 13
  @denied 14
  @cancelled 15

  # ArduPilot's patience with a silent ground station (clock ms): we never give
  # up on an exchange sooner than the vehicle would.
  @vehicle_patience_ms 8_000
  # A timeout's growth over timeouts in a row: 2^3.
  @max_backoff 3

  @doc """
  Starts a transfer, linked to the caller (the vehicle process). `request`:
  `%{operation, sysid, mission_type, items (upload), send, reply_to, progress_to}`.
  Options: `:send_ahead` (`true`, `false`, or `:auto`: when `:autopilot` is
  `:ardupilot`), `:autopilot`, `:window`, `:rtt_ms`, `:loss`, `:attempts`,
  `:restarts`, `:total_timeout_ms`, `:target_component`.
  """
  @spec start_link(map(), keyword()) :: :gen_statem.start_ret()
  def start_link(request, opts \\ []), do: :gen_statem.start_link(__MODULE__, {request, opts}, [])

  @doc "The result atom of a MAV_MISSION_RESULT number."
  @spec result(non_neg_integer()) :: atom()
  def result(n) do
    case M.enum_name(:mav_mission_result, n) do
      {:ok, name} ->
        name |> Atom.to_string() |> String.replace_prefix("mav_mission_", "") |> String.to_atom()

      :error ->
        :"unknown_#{n}"
    end
  end

  @impl true
  def callback_mode, do: [:handle_event_function, :state_enter]

  @impl true
  def init({request, opts}) do
    items = request |> Map.get(:items, []) |> List.to_tuple()
    count = tuple_size(items)

    ahead =
      case Keyword.get(opts, :send_ahead, :auto) do
        :auto -> Keyword.get(opts, :autopilot) == :ardupilot
        other -> other == true
      end

    rtt_ms = Keyword.get(opts, :rtt_ms)

    data =
      Map.merge(request, %{
        type: Map.fetch!(@types, request.mission_type),
        items: items,
        count: count,
        component: Keyword.get(opts, :target_component, 1),
        window: if(ahead, do: Keyword.get(opts, :window, 8), else: 1),
        # The latest round-trip samples (real ms), newest first.
        samples: if(is_number(rtt_ms), do: [rtt_ms], else: []),
        link_loss: Keyword.get(opts, :loss) || 0.0,
        fixed_attempts: Keyword.get(opts, :attempts),
        restarts_left: Keyword.get(opts, :restarts, 4),
        transactions: 1,
        retransmissions: 0,
        # Exchanges that needed a retry, of all: the loss this transfer sees.
        exchanges: 0,
        retried: 0,
        last_answer: nil,
        answered: false,
        # Upload: items ever sent; download: items received.
        sent: MapSet.new(),
        received: %{},
        # Clear: the try a refusal came in answer to (see :clear).
        refused: nil
      })
      |> reset_transaction()

    actions =
      case Keyword.fetch(opts, :total_timeout_ms) do
        {:ok, total} -> [{{:timeout, :total}, Clock.to_real_ms(total), :give_up}]
        :error -> []
      end

    case request.operation do
      :upload -> {:ok, {:count, 0}, data, actions}
      :download -> {:ok, {:list, 0}, data, actions}
      :clear -> {:ok, {:clear, 0}, data, actions}
    end
  end

  # What one transaction (one MISSION_COUNT, one MISSION_REQUEST_LIST) tracks.
  defp reset_transaction(data) do
    Map.merge(data, %{
      # Upload: the item the vehicle asks for (all before it accepted), when it
      # first asked for it, and the next item to send in this pass.
      base: 0,
      base_since: now(),
      next: 0,
      # seq => {real ms of the last send, sends}.
      sends: %{},
      # When items were last sent again from `base`.
      rewound_at: now(),
      # A request for an item before `base`: {seq, first seen}.
      low: nil,
      # Timeouts in a row, and since when nothing moved.
      stalls: 0,
      stalled_since: now(),
      # The vehicle answered an item with MAV_MISSION_ERROR: no upload under way there.
      not_receiving: false,
      # It answered MISSION_COUNT with MAV_MISSION_DENIED.
      denied: false,
      # Download: requested and not received yet, seq => {real ms, sends}.
      asked: %{}
    })
  end

  @impl true
  def handle_event({:timeout, :total}, :give_up, _state, data),
    do: fail(data, :timeout, "time limit reached")

  ## Upload

  def handle_event(:enter, _old, {:count, tries}, data),
    do: open_exchange(data, tries, :count, %M.MissionCount{target_system: data.sysid, target_component: data.component, count: data.count, mission_type: data.type})

  def handle_event(:state_timeout, :rto, {:count, tries}, data) do
    case stall(data) do
      {:retry, data} -> {:next_state, {:count, tries + 1}, data}
      {:give_up, %{denied: true} = data} -> fail(data, :denied, "busy with another ground station's upload")
      {:give_up, data} -> restart_or_fail(data, "no request for items after MISSION_COUNT")
    end
  end

  def handle_event(:enter, _old, :sending, data), do: continue(fill(data))

  def handle_event(:state_timeout, :rto, :sending, data) do
    cond do
      # Its upload is over (it said so for an item we sent): start again.
      data.not_receiving -> restart_or_fail(data, "the vehicle stopped receiving the upload")
      true -> stalled_upload(data)
    end
  end

  def handle_event(:info, {:mission, %m{seq: seq, mission_type: type}}, state, %{operation: :upload} = data)
      when m in [M.MissionRequestInt, M.MissionRequest] and type == data.type and seq < data.count do
    data = heard(data, "asked for item #{seq}")

    case state do
      # A transaction starts at item 0: a request for another is an earlier one's.
      {:count, _} when seq == 0 -> {:next_state, :sending, data |> sample(:count) |> advance(0)}
      {:count, _} -> {:keep_state, data}
      :sending -> request_in_sending(data, seq)
    end
  end

  def handle_event(:info, {:mission, %M.MissionAck{type: result, mission_type: type}}, state, %{operation: :upload} = data)
      when type == data.type do
    upload_ack(result, state, heard(data, "answered #{words(result)}"))
  end

  ## Download

  def handle_event(:enter, _old, {:list, tries}, data),
    do: open_exchange(data, tries, :list, %M.MissionRequestList{target_system: data.sysid, target_component: data.component, mission_type: data.type})

  def handle_event(:state_timeout, :rto, {:list, tries}, data) do
    case stall(data) do
      {:retry, data} -> {:next_state, {:list, tries + 1}, data}
      {:give_up, data} -> restart_or_fail(data, "no MISSION_COUNT after MISSION_REQUEST_LIST")
    end
  end

  def handle_event(:info, {:mission, %M.MissionCount{count: count, mission_type: type}}, {:list, _}, %{operation: :download} = data)
      when type == data.type do
    data = data |> heard("counted #{count} items") |> sample(:list) |> progressed()
    data = %{data | count: count}
    if count == 0, do: finish_download(data), else: {:next_state, :receiving, data}
  end

  def handle_event(:enter, _old, :receiving, data), do: continue(ask(data))

  def handle_event(:state_timeout, :rto, :receiving, data) do
    case stall(data) do
      {:retry, data} ->
        # Everything asked for and not come is asked for again.
        again = map_size(data.asked)
        continue(ask(%{data | asked: %{}, retransmissions: data.retransmissions + again}))

      {:give_up, data} ->
        restart_or_fail(data, "item #{first_missing(data)} never came")
    end
  end

  def handle_event(:info, {:mission, %m{seq: seq, mission_type: type} = item}, :receiving, %{operation: :download} = data)
      when m in [M.MissionItemInt, M.MissionItem] and type == data.type and seq < data.count do
    if Map.has_key?(data.received, seq) do
      # A duplicate.
      :keep_state_and_data
    else
      data = data |> heard("sent item #{seq}") |> sample({:item, seq})

      data =
        %{
          data
          | received: Map.put(data.received, seq, MissionItems.to_int(item)),
            asked: Map.delete(data.asked, seq)
        }
        |> progressed()

      progress(data, map_size(data.received))

      if map_size(data.received) == data.count,
        do: finish_download(data),
        else: continue(ask(data))
    end
  end

  def handle_event(:info, {:mission, %M.MissionAck{type: @unsupported, mission_type: type}}, _state, %{operation: :download} = data)
      when type == data.type,
      do: fail(data, :unsupported, nil)

  # Busy receiving an upload (maybe an earlier one of ours it has not given up
  # yet): asked again at the next timeout. Any other ack is a late one.
  def handle_event(:info, {:mission, %M.MissionAck{type: result, mission_type: type}}, _state, %{operation: :download} = data)
      when type == data.type,
      do: {:keep_state, heard(data, "answered #{words(result)}")}

  ## Clear

  def handle_event(:enter, _old, {:clear, tries}, data),
    do: open_exchange(data, tries, :clear, %M.MissionClearAll{target_system: data.sysid, target_component: data.component, mission_type: data.type})

  def handle_event(:state_timeout, :rto, {:clear, tries}, data) do
    case {stall(data), data.refused} do
      {{:retry, data}, _} -> {:next_state, {:clear, tries + 1}, data}
      {{:give_up, data}, nil} -> give_up(data, "no MISSION_ACK after MISSION_CLEAR_ALL")
      {{:give_up, data}, {_try, result}} -> fail(data, result(result), nil)
    end
  end

  def handle_event(:info, {:mission, %M.MissionAck{type: @accepted, mission_type: type}}, {:clear, _}, %{operation: :clear} = data)
      when type == data.type,
      do: finish(data, :ok)

  # A refusal may be a late answer to something else (an item of the upload
  # before, sent again while the vehicle had it already): the clear goes on
  # as if unanswered, and only a refusal in answer to a later sending is
  # the vehicle's (ArduCopter refuses while its mission runs in AUTO).
  def handle_event(:info, {:mission, %M.MissionAck{type: result, mission_type: type}}, {:clear, tries}, %{operation: :clear} = data)
      when type == data.type do
    case data.refused do
      {earlier, _} when earlier < tries -> fail(data, result(result), nil)
      _ -> {:keep_state, %{data | refused: {tries, result}}}
    end
  end

  # Anything else (duplicates, other mission types, late answers) is not for this state.
  def handle_event(:info, {:mission, _message}, _state, _data), do: :keep_state_and_data

  # The first message of an exchange (MISSION_COUNT, MISSION_REQUEST_LIST,
  # MISSION_CLEAR_ALL), sent again on every try after the first.
  defp open_exchange(data, tries, what, message) do
    data = if tries > 0, do: bump(data, :retransmissions), else: data
    data.send.(message)
    continue(sent_now(data, what))
  end

  ## Upload: the vehicle's requests and acks

  defp request_in_sending(data, seq) do
    cond do
      seq > data.base ->
        data |> sample({:item, seq - 1}) |> advance(seq) |> fill() |> continue()

      # The same request again: a duplicate (ArduPilot asks twice at times),
      # unless the item went out long enough ago to have come back: then the
      # vehicle did not get it.
      seq == data.base ->
        if now() - max(data.base_since, last_send(data, seq)) >= rto_ms(data),
          do: continue(rewind(data)),
          else: {:keep_state, data}

      # A request for an item the vehicle has already accepted is a late one;
      # but the same one again a while later is the vehicle's (a duplicated
      # MISSION_COUNT restarted its upload): begin again from there.
      true ->
        case data.low do
          {^seq, since} ->
            if now() - since >= 2 * rto_ms(data),
              do: data |> advance(seq) |> Map.put(:next, seq) |> rewind() |> continue(),
              else: {:keep_state, data}

          _ ->
            {:keep_state, %{data | low: {seq, now()}}}
        end
    end
  end

  defp upload_ack(@accepted, :sending, data) do
    # ACCEPTED before every item went out is not this transfer's answer.
    if MapSet.size(data.sent) == data.count, do: finish(data, :ok), else: {:keep_state, data}
  end

  # An item the vehicle did not expect: with items in flight past the one it
  # wants, a gap. Every item of the window after the gap draws one, and items
  # sent before the last resend still do for a round trip: one resend per
  # retransmission timeout, or they would multiply.
  defp upload_ack(@invalid_sequence, :sending, data) do
    if data.window > 1 and data.next > data.base + 1 and now() - data.rewound_at >= rto_ms(data),
      do: continue(rewind(data)),
      else: {:keep_state, data}
  end

  # No upload under way on the vehicle. Once every item went out, and the
  # vehicle took one well within its patience (half of it: what it last
  # asked for is stamped when this process reads it, which a busy host
  # delays), it did not give up: it took the last one and its ACCEPTED was
  # lost, which only reading the mission back can confirm. Otherwise it may
  # have given up: the next timeout starts again.
  defp upload_ack(@error, :sending, data) do
    if MapSet.size(data.sent) == data.count and now() - data.stalled_since < Clock.to_real_ms(@vehicle_patience_ms) / 2,
      do: fail(data, :unconfirmed, "every item was sent, but the vehicle's MISSION_ACK never came and it is no longer receiving"),
      else: {:keep_state, %{data | not_receiving: true}}
  end

  defp upload_ack(@cancelled, :sending, data),
    do: restart_or_fail(data, "the vehicle cancelled the upload")

  defp upload_ack(result, _state, data)
       when result in [@accepted, @error, @invalid_sequence, @cancelled],
       do: {:keep_state, data}

  # DENIED after an item names another ground station's upload. To our
  # COUNT too (ArduPilot denies a COUNT while another station uploads), or
  # it is a late answer to a request of a download just before (denied
  # while a duplicated COUNT had the vehicle receiving): asked again at the
  # next timeout, and said if the upload is given up.
  defp upload_ack(@denied, :sending, data), do: {:keep_state, data}
  defp upload_ack(@denied, {:count, _}, data), do: {:keep_state, %{data | denied: true}}
  defp upload_ack(result, _state, data), do: fail(data, result(result), nil)

  # The vehicle asks for `seq`: every item before it is accepted.
  defp advance(data, seq) do
    progressed(%{
      data
      | base: seq,
        base_since: now(),
        next: max(data.next, seq),
        low: nil,
        not_receiving: false
    })
  end

  # Keeps the window full: the items from `next` up to `base + window`.
  defp fill(%{next: next, base: base, window: w, count: count} = data)
       when next < count and next < base + w,
       do: fill(%{send_item(data, next) | next: next + 1})

  defp fill(data), do: data

  # Sends again from the item the vehicle wants.
  defp rewind(data), do: fill(%{data | next: data.base, rewound_at: now()})

  defp stalled_upload(data) do
    case stall(data) do
      {:retry, data} ->
        continue(rewind(data))

      {:give_up, data} ->
        restart_or_fail(
          data,
          "the vehicle stopped asking for items (it last #{data.last_answer || "said nothing"})"
        )
    end
  end

  defp send_item(data, seq) do
    item = %{
      elem(data.items, seq)
      | seq: seq,
        target_system: data.sysid,
        target_component: data.component,
        mission_type: data.type
    }

    data.send.(item)
    again? = MapSet.member?(data.sent, seq)
    data = %{data | sent: MapSet.put(data.sent, seq)} |> sent_now({:item, seq})

    if again?,
      do: bump(data, :retransmissions),
      else: tap(data, &progress(&1, MapSet.size(&1.sent)))
  end

  ## Download: asking for items

  # Asks for the lowest missing items not asked for yet, up to the window.
  defp ask(data) do
    want =
      0..(data.count - 1)//1
      |> Stream.reject(&Map.has_key?(data.received, &1))
      |> Enum.take(data.window)

    Enum.reduce(want, data, fn seq, d ->
      if Map.has_key?(d.asked, seq) do
        d
      else
        d.send.(%M.MissionRequestInt{target_system: d.sysid, target_component: d.component, seq: seq, mission_type: d.type})

        sent_now(%{d | asked: Map.put(d.asked, seq, true)}, {:item, seq})
      end
    end)
  end

  defp first_missing(data),
    do: Enum.find(0..(data.count - 1)//1, &(not Map.has_key?(data.received, &1)))

  ## Round trips, timeouts, budgets

  defp now, do: System.monotonic_time(:millisecond)

  # Remembers when `what` was sent, and how often.
  defp sent_now(data, what) do
    {_, n} = Map.get(data.sends, what, {0, 0})
    %{data | sends: Map.put(data.sends, what, {now(), n + 1})}
  end

  defp last_send(data, seq) do
    {at, _} = Map.get(data.sends, {:item, seq}, {0, 0})
    at
  end

  # An answer to `what`: a round-trip sample if it was sent once (an answer to
  # a resent one could be to either send). Until the first sample, an answer
  # to a resent one is measured from the last send: too short at worst, which
  # costs a resend, where no sample at all leaves every timeout at a second.
  defp sample(data, what) do
    case Map.get(data.sends, what) do
      {at, 1} -> rtt_sample(data, now() - at)
      {at, _} when data.samples == [] -> rtt_sample(data, now() - at)
      _ -> data
    end
  end

  @samples 16
  defp rtt_sample(data, r), do: %{data | samples: Enum.take([r | data.samples], @samples)}

  # The vehicle asks again itself after a second: no use waiting longer.
  defp rto_ms(data), do: Retry.timeout(data.samples, 1_000)

  # Goes on in the same state, the retransmission timer started again.
  defp continue(data), do: {:keep_state, data, [rto(data)]}

  # Doubled at every timeout in a row, up to 8 times or a second of clock
  # time, whichever is less (but never under the timeout itself).
  defp rto(data) do
    base = rto_ms(data)
    {:state_timeout, min(base * Bitwise.bsl(1, min(data.stalls, @max_backoff)), max(base, Clock.retry_real_ms(1_000))), :rto}
  end

  # Something moved: the timeouts in a row start again.
  defp progressed(data),
    do: %{data | stalls: 0, stalled_since: now(), exchanges: data.exchanges + 1}

  defp heard(data, what), do: %{data | last_answer: what, answered: true}

  # One more timeout in a row: retry, or give the exchange up.
  defp stall(data) do
    data = %{
      data
      | stalls: data.stalls + 1,
        retried: data.retried + 1,
        exchanges: data.exchanges + 1
    }

    over? =
      case data.fixed_attempts do
        nil ->
          data.stalls >= Retry.attempts(loss(data)) and
            now() - data.stalled_since >= Retry.patience_real_ms(@vehicle_patience_ms)

        n ->
          data.stalls >= n
      end

    if over?, do: {:give_up, data}, else: {:retry, data}
  end

  # The round-trip loss to plan for: the link's, or what this transfer has
  # seen, and never less than a bad radio's 30 % until a few exchanges show it.
  defp loss(data) do
    seen = if data.exchanges >= 20, do: data.retried / data.exchanges, else: 0.3
    max(max(data.link_loss, seen), 0.0)
  end

  defp restart_or_fail(data, why) do
    if data.answered and data.restarts_left > 0 and data.operation != :clear do
      data = %{
        reset_transaction(data)
        | restarts_left: data.restarts_left - 1,
          transactions: data.transactions + 1,
          answered: false
      }

      data = bump(data, :retransmissions)

      case data.operation do
        :upload -> {:next_state, {:count, 0}, data}
        :download -> {:next_state, {:list, 0}, %{data | received: %{}}}
      end
    else
      give_up(data, why)
    end
  end

  defp give_up(data, why) do
    tried = if data.transactions > 1, do: " after #{data.transactions} attempts", else: ""

    last =
      if data.last_answer,
        do: "; the vehicle last #{data.last_answer}",
        else: "; the vehicle never answered"

    fail(data, :timeout, why <> tried <> last)
  end

  defp bump(data, key), do: Map.update!(data, key, &(&1 + 1))

  defp words(result),
    do: "MAV_MISSION_" <> (result |> result() |> Atom.to_string() |> String.upcase())

  ## Endings

  defp finish_download(data) do
    data.send.(%M.MissionAck{target_system: data.sysid, target_component: data.component, type: @accepted, mission_type: data.type})

    finish(data, {:ok, Enum.map(0..(data.count - 1)//1, &Map.fetch!(data.received, &1))})
  end

  defp progress(%{progress_to: pid} = data, done) when is_pid(pid),
    do: send(pid, {:mission_progress, data.operation, done, data.count})

  defp progress(_data, _done), do: :ok

  defp finish(data, reply) do
    if is_pid(data[:progress_to]),
      do:
        send(
          data.progress_to,
          {:mission_done, data.operation, %{retransmissions: data.retransmissions, transactions: data.transactions}}
        )

    :gen_statem.reply(data.reply_to, reply)
    {:stop, :normal, data}
  end

  defp fail(data, result, detail) do
    error = %MissionError{operation: data.operation, vehicle: Map.get(data, :vehicle, data.sysid), mission_type: data.mission_type, result: result, detail: detail}

    finish(data, {:error, error})
  end
end
