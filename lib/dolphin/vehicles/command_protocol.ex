defmodule Dolphin.Vehicles.CommandProtocol do
  @moduledoc """
  The MAVLink command protocol for one command to one vehicle, as a
  `:gen_statem` started by the vehicle's process (which routes the vehicle's
  COMMAND_ACKs for that command id to it).

  States:

    * `{:waiting, attempt}` — the command was sent with `confirmation` =
      attempt - 1; with no COMMAND_ACK within `:ack_timeout_ms` of clock time it
      is sent again with the confirmation incremented, up to `:attempts` times
      (the spec's retransmission); then `{:error, %Dolphin.CommandError{result:
      :timeout}}`.
    * `:in_progress` — the vehicle answered MAV_RESULT_IN_PROGRESS: no more
      retransmission; each further IN_PROGRESS (with `progress`) restarts the
      `:progress_timeout_ms` wait for the final answer.

  A final COMMAND_ACK ends it: ACCEPTED is `{:ok, :accepted}`, anything else
  `{:error, %Dolphin.CommandError{}}`. The reply goes to the caller given at
  start (`GenServer.reply/2`), and progress, if asked for, as messages
  `{:command_progress, command, percent}` to `:progress_to`.
  """

  @behaviour :gen_statem

  alias Dolphin.{Clock, CommandError}
  alias Dolphin.Vehicles.Retry
  alias Dolphin.MAVLink.Ardupilotmega, as: M

  @results %{
    0 => :accepted,
    1 => :temporarily_rejected,
    2 => :denied,
    3 => :unsupported,
    4 => :failed,
    5 => :in_progress,
    6 => :cancelled,
    7 => :command_long_only,
    8 => :command_int_only,
    9 => :unsupported_mav_frame
  }

  @doc """
  Starts the protocol, linked to the caller (the vehicle process). `request`:
  `%{sysid, target_component, command, params, int, frame, send, reply_to,
  progress_to}` — `params` are the 7 parameters (for COMMAND_INT, `int: true`,
  params 1-4, then `x`, `y` as integers and `z`), `send` a function that sends
  a message to the vehicle, `reply_to` a `GenServer.from()`. Options
  `:attempts` (default: as many as the link's round-trip loss `:loss` calls
  for, `Dolphin.Vehicles.Retry.attempts/1`: 5 on a clean link, 12 when it is
  not measured, 21 at 30 % each way, and as many more as fit in 5 s of real
  time, `Dolphin.Vehicles.Retry.patience_real_ms/2`), `:ack_timeout_ms` (the longest wait,
  default 1_500 of clock time; with the link's round trip `:rtt_ms` known,
  twice `Dolphin.Vehicles.Retry.timeout/3` of it but not under 250 ms of
  clock time, for the vehicle's own work), `:progress_timeout_ms` (default
  30_000).
  """
  @spec start_link(map(), keyword()) :: :gen_statem.start_ret()
  def start_link(request, opts \\ []), do: :gen_statem.start_link(__MODULE__, {request, opts}, [])

  @doc "The result atom of a MAV_RESULT number."
  @spec result(non_neg_integer()) :: atom()
  def result(n), do: Map.get(@results, n, :"unknown_#{n}")

  @impl true
  def callback_mode, do: [:handle_event_function, :state_enter]

  @impl true
  def init({request, opts}) do
    data =
      Map.merge(request, %{
        attempts: Keyword.get_lazy(opts, :attempts, fn -> Retry.attempts(Keyword.get(opts, :loss)) end),
        # Given attempts are exact; the link's are tried for at least the least patience too.
        first_sent_at: Retry.patience_from(opts),
        wait_ms: Retry.answer_wait(Keyword.get(opts, :ack_timeout_ms, 1_500), Keyword.get(opts, :rtt_ms)),
        progress_timeout_ms: Keyword.get(opts, :progress_timeout_ms, 30_000),
        sent: 0
      })

    {:ok, {:waiting, 1}, data}
  end

  @impl true
  # Entering {:waiting, n} sends attempt n (confirmation n - 1, as the spec asks
  # of a retransmission) and waits for the COMMAND_ACK.
  def handle_event(:enter, _old, {:waiting, n}, data) do
    data.send.(message(data, n - 1))
    {:keep_state, %{data | sent: n}, [{:state_timeout, data.wait_ms, :resend}]}
  end

  def handle_event(:state_timeout, :resend, {:waiting, n}, data) do
    if n < data.attempts or Retry.patient?(data.first_sent_at),
      do: {:next_state, {:waiting, n + 1}, data},
      else: finish(data, {:error, error(data, :timeout, nil)})
  end

  # IN_PROGRESS: no more retransmission, a longer wait for the final answer.
  def handle_event(:enter, _old, :in_progress, data),
    do: {:keep_state_and_data, [{:state_timeout, Clock.to_real_ms(data.progress_timeout_ms), :gave_up}]}

  def handle_event(:state_timeout, :gave_up, :in_progress, data),
    do: finish(data, {:error, error(data, :timeout, "no final answer after IN_PROGRESS")})

  # An answer from another component than the one asked is not this command's.
  def handle_event(:info, {:ack, _ack, compid}, _state, %{target_component: target})
      when target != 0 and compid != target,
      do: :keep_state_and_data

  def handle_event(:info, {:ack, ack, _compid}, state, data), do: handle_event(:info, {:ack, ack}, state, data)

  def handle_event(:info, {:ack, %M.CommandAck{result: 5, progress: progress}}, state, data) do
    if data[:progress_to], do: send(data.progress_to, {:command_progress, data.command, progress})
    # Each IN_PROGRESS restarts the wait.
    if state == :in_progress, do: {:repeat_state, data}, else: {:next_state, :in_progress, data}
  end

  def handle_event(:info, {:ack, %M.CommandAck{result: 0}}, _state, data), do: finish(data, {:ok, :accepted})

  def handle_event(:info, {:ack, %M.CommandAck{result: n, result_param2: param2}}, _state, data) do
    detail = if param2 != 0, do: "result_param2 #{param2}"
    finish(data, {:error, error(data, result(n), detail)})
  end

  defp finish(data, reply) do
    if data.reply_to, do: :gen_statem.reply(data.reply_to, reply)
    {:stop, :normal, data}
  end

  defp error(data, result, detail) do
    %CommandError{command: name(data.command), vehicle: Map.get(data, :vehicle, data.sysid), result: result, attempts: data.sent, detail: detail}
  end

  defp name(command) do
    case M.enum_name(:mav_cmd, command) do
      {:ok, name} -> name
      :error -> command
    end
  end

  defp message(%{int: true} = data, _confirmation) do
    [p1, p2, p3, p4, x, y, z] = data.params

    %M.CommandInt{
      target_system: data.sysid,
      target_component: data.target_component,
      frame: data.frame,
      command: data.command,
      param1: p1,
      param2: p2,
      param3: p3,
      param4: p4,
      x: x,
      y: y,
      z: z
    }
  end

  defp message(data, confirmation) do
    [p1, p2, p3, p4, p5, p6, p7] = data.params

    %M.CommandLong{
      target_system: data.sysid,
      target_component: data.target_component,
      command: data.command,
      confirmation: min(confirmation, 255),
      param1: p1,
      param2: p2,
      param3: p3,
      param4: p4,
      param5: p5,
      param6: p6,
      param7: p7
    }
  end
end
