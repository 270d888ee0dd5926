defmodule Dolphin.Vehicles.MissionProtocol do
  @moduledoc """
  The MAVLink mission protocol for one transfer with one vehicle, as a
  `:gen_statem` started by the vehicle's process (which routes the vehicle's
  mission messages to it). Works for the mission, fence and rally lists.

  **Upload** (`:upload`, items as `MISSION_ITEM_INT` structs; `seq`, target and
  mission type are filled in): `{:count, attempt}` sends MISSION_COUNT until the
  vehicle asks for an item; `:sending` answers every MISSION_REQUEST_INT or
  MISSION_REQUEST (ArduCopter sends the latter) with that item — duplicate and
  out-of-order requests included — and resends the last item asked for when the
  vehicle falls silent. MISSION_ACK ends it (but INVALID_SEQUENCE, which
  ArduPilot sends for an unexpected item while it goes on asking for the one it
  wants). An ACCEPTED ack counts only once
  every item has been sent at least once: a stale or duplicated ack from an
  earlier transfer, which a lossy link can deliver late, never makes a wrong
  mission look accepted. ArduPilot treats item 0 as home.

  **Download** (`:download`): `{:list, attempt}` sends MISSION_REQUEST_LIST
  until MISSION_COUNT; `{:item, seq, attempt}` asks for each item with
  MISSION_REQUEST_INT until it comes (MISSION_ITEM_INT, or the older
  MISSION_ITEM, converted); then MISSION_ACK.

  **Clear** (`:clear`): MISSION_CLEAR_ALL until MISSION_ACK.

  Every wait is `:item_timeout_ms` of clock time (default 1_500), retried up to
  `:attempts` times (default 5); the whole transfer is bounded by
  `:total_timeout_ms` (default 10 s + 1 s per item). The result goes to the
  caller: `:ok`, `{:ok, items}` (download), or `{:error, %Dolphin.MissionError{}}`;
  progress, if asked for, as `{:mission_progress, operation, done, total}`,
  and at the end `{:mission_done, operation, %{retransmissions: n}}` (items and
  MISSION_COUNTs sent again).
  """

  @behaviour :gen_statem

  alias Dolphin.{Clock, MissionError}
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.MissionItems

  @types %{mission: 0, fence: 1, rally: 2}

  @doc """
  Starts a transfer, linked to the caller (the vehicle process). `request`:
  `%{operation, sysid, mission_type, items (upload), send, reply_to, progress_to}`.
  """
  @spec start_link(map(), keyword()) :: :gen_statem.start_ret()
  def start_link(request, opts \\ []), do: :gen_statem.start_link(__MODULE__, {request, opts}, [])

  @doc "The result atom of a MAV_MISSION_RESULT number."
  @spec result(non_neg_integer()) :: atom()
  def result(n) do
    case M.enum_name(:mav_mission_result, n) do
      {:ok, name} -> name |> Atom.to_string() |> String.replace_prefix("mav_mission_", "") |> String.to_atom()
      :error -> :"unknown_#{n}"
    end
  end

  @impl true
  def callback_mode, do: [:handle_event_function, :state_enter]

  @impl true
  def init({request, opts}) do
    items = request |> Map.get(:items, []) |> List.to_tuple()
    count = tuple_size(items)

    data =
      Map.merge(request, %{
        type: Map.fetch!(@types, request.mission_type),
        items: items,
        count: count,
        sent: MapSet.new(),
        retransmissions: 0,
        last: nil,
        received: %{},
        attempts: Keyword.get(opts, :attempts, 5),
        item_timeout_ms: Keyword.get(opts, :item_timeout_ms, 1_500),
        component: Keyword.get(opts, :target_component, 1)
      })

    total = Keyword.get(opts, :total_timeout_ms, 10_000 + 1_000 * count)
    data = Map.put(data, :fixed_total, Keyword.has_key?(opts, :total_timeout_ms))
    # The limit of the whole transfer, whatever the retries.
    actions = [{{:timeout, :total}, Clock.to_real_ms(total), :give_up}]

    case request.operation do
      :upload -> {:ok, {:count, 1}, data, actions}
      :download -> {:ok, {:list, 1}, data, actions}
      :clear -> {:ok, {:clear, 1}, data, actions}
    end
  end

  @impl true
  def handle_event({:timeout, :total}, :give_up, _state, data), do: fail(data, :timeout, "time limit reached")

  ## Upload

  def handle_event(:enter, _old, {:count, n}, data) do
    data = if n > 1, do: %{data | retransmissions: data.retransmissions + 1}, else: data
    data.send.(%M.MissionCount{target_system: data.sysid, target_component: data.component, count: data.count, mission_type: data.type})
    wait(data)
  end

  # Waits are retried by re-entering the state with the next attempt number.
  def handle_event(:state_timeout, :retry, {:count, n}, data) when n < data.attempts, do: {:next_state, {:count, n + 1}, data}
  def handle_event(:state_timeout, :retry, {:count, _}, data), do: fail(data, :timeout, "no request for items after MISSION_COUNT")

  def handle_event(:enter, _old, :sending, data), do: wait(data)

  def handle_event(:state_timeout, :retry, :sending, %{last: {seq, n}} = data) when n < data.attempts do
    data = send_item(data, seq, n + 1)
    {:keep_state, data, [timeout(data)]}
  end

  def handle_event(:state_timeout, :retry, :sending, data), do: fail(data, :timeout, "the vehicle stopped asking for items")

  def handle_event(:info, {:mission, %m{seq: seq, mission_type: type}}, state, %{operation: :upload} = data)
      when m in [M.MissionRequestInt, M.MissionRequest] and type == data.type do
    cond do
      seq >= data.count ->
        # Answered by the vehicle's own checks; nothing to send.
        :keep_state_and_data

      match?({:count, _}, state) ->
        {:next_state, :sending, send_item(data, seq, 1)}

      true ->
        {:keep_state, send_item(data, seq, 1), [timeout(data)]}
    end
  end

  def handle_event(:info, {:mission, %M.MissionAck{type: 0, mission_type: type}}, _state, %{operation: :upload} = data)
      when type == data.type do
    # ACCEPTED before every item went out is not this transfer's answer.
    if MapSet.size(data.sent) == data.count, do: finish(data, :ok), else: :keep_state_and_data
  end

  # INVALID_SEQUENCE answers an item the vehicle did not expect (a duplicate, a
  # late retransmission): ArduPilot keeps asking for the one it wants, so the
  # transfer goes on.
  def handle_event(:info, {:mission, %M.MissionAck{type: 13, mission_type: type}}, _state, %{operation: :upload} = data)
      when type == data.type,
      do: :keep_state_and_data

  def handle_event(:info, {:mission, %M.MissionAck{type: result, mission_type: type}}, _state, %{operation: :upload} = data)
      when type == data.type,
      do: fail(data, result(result), nil)

  ## Download

  def handle_event(:enter, _old, {:list, _n}, data) do
    data.send.(%M.MissionRequestList{target_system: data.sysid, target_component: data.component, mission_type: data.type})
    wait(data)
  end

  def handle_event(:state_timeout, :retry, {:list, n}, data) when n < data.attempts, do: {:next_state, {:list, n + 1}, data}
  def handle_event(:state_timeout, :retry, {:list, _}, data), do: fail(data, :timeout, "no MISSION_COUNT")

  def handle_event(:info, {:mission, %M.MissionCount{count: count, mission_type: type}}, {:list, _}, %{operation: :download} = data)
      when type == data.type do
    data = %{data | count: count}
    # The limit grows with the items the vehicle announced (unless set by the caller).
    limit = if data.fixed_total, do: [], else: [{{:timeout, :total}, Clock.to_real_ms(10_000 + 1_000 * count), :give_up}]
    if count == 0, do: finish_download(data), else: {:next_state, {:item, 0, 1}, data, limit}
  end

  def handle_event(:enter, _old, {:item, seq, _n}, data) do
    data.send.(%M.MissionRequestInt{target_system: data.sysid, target_component: data.component, seq: seq, mission_type: data.type})
    wait(data)
  end

  def handle_event(:state_timeout, :retry, {:item, seq, n}, data) when n < data.attempts,
    do: {:next_state, {:item, seq, n + 1}, data}

  def handle_event(:state_timeout, :retry, {:item, seq, _}, data), do: fail(data, :timeout, "item #{seq} never came")

  def handle_event(:info, {:mission, %m{seq: seq, mission_type: type} = item}, {:item, seq, _n}, %{operation: :download} = data)
      when m in [M.MissionItemInt, M.MissionItem] and type == data.type do
    data = %{data | received: Map.put(data.received, seq, MissionItems.to_int(item))}
    progress(data, seq + 1)
    if seq + 1 == data.count, do: finish_download(data), else: {:next_state, {:item, seq + 1, 1}, data}
  end

  def handle_event(:info, {:mission, %M.MissionAck{type: result, mission_type: type}}, _state, %{operation: :download} = data)
      when type == data.type and result != 0,
      do: fail(data, result(result), nil)

  ## Clear

  def handle_event(:enter, _old, {:clear, _n}, data) do
    data.send.(%M.MissionClearAll{target_system: data.sysid, target_component: data.component, mission_type: data.type})
    wait(data)
  end

  def handle_event(:state_timeout, :retry, {:clear, n}, data) when n < data.attempts, do: {:next_state, {:clear, n + 1}, data}
  def handle_event(:state_timeout, :retry, {:clear, _}, data), do: fail(data, :timeout, "no MISSION_ACK")

  def handle_event(:info, {:mission, %M.MissionAck{type: 0, mission_type: type}}, {:clear, _}, %{operation: :clear} = data)
      when type == data.type,
      do: finish(data, :ok)

  def handle_event(:info, {:mission, %M.MissionAck{type: result, mission_type: type}}, {:clear, _}, %{operation: :clear} = data)
      when type == data.type,
      do: fail(data, result(result), nil)

  # Anything else (duplicates, other mission types, late answers) is not for this state.
  def handle_event(:info, {:mission, _message}, _state, _data), do: :keep_state_and_data

  ## Helpers

  defp wait(data), do: {:keep_state, data, [timeout(data)]}
  defp timeout(data), do: {:state_timeout, Clock.retry_real_ms(data.item_timeout_ms), :retry}

  defp send_item(data, seq, attempt) do
    item = %{elem(data.items, seq) | seq: seq, target_system: data.sysid, target_component: data.component, mission_type: data.type}
    data.send.(item)
    sent = MapSet.put(data.sent, seq)
    again = if MapSet.member?(data.sent, seq), do: 1, else: 0
    if again == 0, do: progress(data, MapSet.size(sent))
    %{data | sent: sent, last: {seq, attempt}, retransmissions: data.retransmissions + again}
  end

  defp finish_download(data) do
    data.send.(%M.MissionAck{target_system: data.sysid, target_component: data.component, type: 0, mission_type: data.type})
    finish(data, {:ok, Enum.map(0..(data.count - 1)//1, &Map.fetch!(data.received, &1))})
  end

  defp progress(%{progress_to: pid} = data, done) when is_pid(pid), do: send(pid, {:mission_progress, data.operation, done, data.count})
  defp progress(_data, _done), do: :ok

  defp finish(data, reply) do
    if is_pid(data[:progress_to]), do: send(data.progress_to, {:mission_done, data.operation, %{retransmissions: data.retransmissions}})
    :gen_statem.reply(data.reply_to, reply)
    {:stop, :normal, data}
  end

  defp fail(data, result, detail) do
    error = %MissionError{operation: data.operation, vehicle: data.sysid, mission_type: data.mission_type, result: result, detail: detail}
    finish(data, {:error, error})
  end
end
