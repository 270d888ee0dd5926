defmodule Dolphin.Vehicles.ParamList do
  @moduledoc """
  A vehicle's whole parameter list, fetched with the MAVLink parameter
  protocol, as a `:gen_statem` started by the vehicle's process (which
  routes every PARAM_VALUE to it): PARAM_REQUEST_LIST, then each
  PARAM_VALUE kept by its `param_index` (of `param_count`). Once the values
  pause (a quarter of the wait for an answer, at least 250 ms; a second
  before the first), the ones still missing are asked for by index
  (PARAM_REQUEST_READ), fifty at a time, again and again while each round
  brings some: a lossy link costs the missing ones, never a restart. It
  ends with every parameter, or with an error once `attempts` rounds in a
  row bring nothing (and, unless the attempts were given, the least
  patience has passed since anything came: `Dolphin.Vehicles.Retry.patient?/1`).

  The reply is `{:ok, [%{name, value, type, index}]}` in index order —
  `value` typed by MAV_PARAM_TYPE (an integer for the integer types,
  `Dolphin.Vehicles.ParamProtocol.typed/2`) — or `{:error,
  %Dolphin.ParamError{result: :timeout}}` saying how many are missing.
  """

  @behaviour :gen_statem

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.ParamError
  alias Dolphin.Vehicles.{ParamProtocol, Retry}

  # Missing parameters asked for at once, by index.
  @batch 50
  # Real ms a round lasts at least, and before the list's first value.
  @least_round_ms 250
  @least_first_ms 1_000

  @doc """
  Starts the protocol, linked to the caller (the vehicle process).
  `request`: `%{sysid, vehicle, send, reply_to}`, and `owner`, the
  vehicle's process, which is sent `{:param_names, count, names}` when a
  whole list came. Options: `:attempts`
  (rounds in a row that may bring nothing), `:loss`, `:rtt_ms`,
  `:ack_timeout_ms` (as `Dolphin.Vehicles.ParamProtocol`'s).
  """
  @spec start_link(map(), keyword()) :: :gen_statem.start_ret()
  def start_link(request, opts \\ []), do: :gen_statem.start_link(__MODULE__, {request, opts}, [])

  @impl true
  def callback_mode, do: :handle_event_function

  @impl true
  def init({request, opts}) do
    # Never shorter than an autopilot takes to start its list (ArduPilot
    # sends it from its main loop, at a pace of its own, whatever the
    # clock's speed-up) or to answer a few reads.
    answer = Retry.answer_wait(Keyword.get(opts, :ack_timeout_ms, 1_500), Keyword.get(opts, :rtt_ms))
    wait = max(answer, @least_round_ms)
    attempts = Keyword.get_lazy(opts, :attempts, fn -> Retry.attempts(Keyword.get(opts, :loss)) end)
    # Once values come, a pause this long between two of them ends the round.
    gap = max(div(wait, 4), 100)

    data =
      Map.merge(request, %{
        attempts: attempts,
        # Given attempts are exact; the link's are tried for at least the least patience too.
        progress_at: Retry.patience_from(opts),
        wait_ms: wait,
        first_ms: max(wait, @least_first_ms),
        gap_ms: gap,
        count: nil,
        values: %{},
        fruitless: 0,
        received: 0,
        rounds: 1,
        asked: []
      })

    data.send.(%M.ParamRequestList{target_system: data.sysid, target_component: 1})
    {:ok, :listing, data, [{:state_timeout, data.first_ms, :quiet}]}
  end

  @impl true
  # A value of the list (a PARAM_VALUE of a set elsewhere, index 65535 or
  # of another count, is not one).
  def handle_event(:info, {:param, %M.ParamValue{param_index: i, param_count: n} = v}, _state, data)
      when i < n and (data.count == nil or data.count == n) do
    fresh? = not Map.has_key?(data.values, i)
    data = %{data | count: n, values: Map.put(data.values, i, v), received: data.received + if(fresh?, do: 1, else: 0)}

    cond do
      map_size(data.values) == n -> finish(data, {:ok, list(data)})
      # Every one asked for in this round came: the next round at once.
      data.asked != [] and Enum.all?(data.asked, &Map.has_key?(data.values, &1)) -> next_round(data)
      # Values still coming: the round goes on until they pause.
      true -> {:keep_state, data, [{:state_timeout, data.gap_ms, :quiet}]}
    end
  end

  # Another count: the vehicle's list changed under us (parameters appear
  # when a feature is enabled); its indexes may have moved, so it is taken
  # anew, from what comes now.
  def handle_event(:info, {:param, %M.ParamValue{param_index: i, param_count: n}} = msg, state, data) when i < n and n != data.count,
    do: handle_event(:info, msg, state, %{data | count: nil, values: %{}, received: 0})

  def handle_event(:info, {:param, _other}, _state, _data), do: :keep_state_and_data

  def handle_event(:state_timeout, :quiet, _state, data), do: next_round(data)

  # A round is over (quiet, or all it asked for came). One that brought
  # nothing new counts against the attempts.
  defp next_round(data) do
    fruitless = if data.received == 0, do: data.fruitless + 1, else: 0
    progress = if data.received > 0 and data.progress_at, do: System.monotonic_time(:millisecond), else: data.progress_at
    data = %{data | fruitless: fruitless, received: 0, rounds: data.rounds + 1, progress_at: progress}

    cond do
      fruitless >= data.attempts and not Retry.patient?(progress) ->
        missing = if data.count, do: data.count - map_size(data.values), else: nil
        detail = if missing, do: "#{missing} of #{data.count} parameters not received", else: "no parameter received"
        finish(data, {:error, %ParamError{param: "(the list)", vehicle: data.vehicle, result: :timeout, attempts: data.rounds - 1, detail: detail}})

      data.count == nil ->
        data.send.(%M.ParamRequestList{target_system: data.sysid, target_component: 1})
        {:next_state, :listing, data, [{:state_timeout, data.first_ms, :quiet}]}

      true ->
        missing = Enum.reject(0..(data.count - 1), &Map.has_key?(data.values, &1)) |> Enum.take(@batch)
        for i <- missing, do: data.send.(%M.ParamRequestRead{target_system: data.sysid, target_component: 1, param_id: "", param_index: i})
        {:next_state, :filling, %{data | asked: missing}, [{:state_timeout, data.wait_ms, :quiet}]}
    end
  end

  defp list(data) do
    for {i, v} <- Enum.sort(data.values), do: %{name: v.param_id, value: ParamProtocol.typed(v.param_value, v.param_type), type: v.param_type, index: i}
  end

  defp finish(data, reply) do
    if data.reply_to, do: :gen_statem.reply(data.reply_to, reply)
    # The vehicle keeps the names of a whole list (Dolphin.Vehicles.param/4 tells an unknown name by them).
    with {:ok, list} <- reply, %{owner: owner} <- data, do: send(owner, {:param_names, data.count, MapSet.new(list, & &1.name)})
    {:stop, :normal, data}
  end
end
