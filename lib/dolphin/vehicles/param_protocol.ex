defmodule Dolphin.Vehicles.ParamProtocol do
  @moduledoc """
  The MAVLink parameter protocol for one parameter of one vehicle, as a
  `:gen_statem` started by the vehicle's process (which routes the vehicle's
  PARAM_VALUEs for that name to it): a set (PARAM_SET, answered by the
  PARAM_VALUE the vehicle keeps) or a read (PARAM_REQUEST_READ). Sent again
  when no answer comes within the wait, as the command protocol does
  (`Dolphin.Vehicles.Retry`); a set answered with another value than asked
  (it keeps a whole number for an integer type, or bounds the value) is
  `{:error, %Dolphin.ParamError{result: :refused}}`; otherwise the reply is
  `{:ok, value}` to the caller given at start.
  """

  @behaviour :gen_statem

  alias Dolphin.ParamError
  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Vehicles.Retry

  # MAV_PARAM_TYPE_REAL32: ArduPilot keeps every parameter as a float on the wire.
  @real32 9

  @doc """
  Starts the protocol, linked to the caller (the vehicle process).
  `request`: `%{sysid, vehicle, name, value (nil: a read), send, reply_to}`,
  and `typed: true` for the value typed by its MAV_PARAM_TYPE (`typed/2`).
  Options as `Dolphin.Vehicles.CommandProtocol.start_link/2`'s: `:attempts`
  (given, exact; else as many as the link's `:loss` calls for, and as many
  more as fit in the least patience, `Dolphin.Vehicles.Retry.patient?/1`),
  `:loss`, `:rtt_ms`, `:ack_timeout_ms`.
  """
  @spec start_link(map(), keyword()) :: :gen_statem.start_ret()
  def start_link(request, opts \\ []), do: :gen_statem.start_link(__MODULE__, {request, opts}, [])

  @impl true
  def callback_mode, do: [:handle_event_function, :state_enter]

  @impl true
  def init({request, opts}) do
    wait = Retry.answer_wait(Keyword.get(opts, :ack_timeout_ms, 1_500), Keyword.get(opts, :rtt_ms))
    attempts = Keyword.get_lazy(opts, :attempts, fn -> Retry.attempts(Keyword.get(opts, :loss)) end)
    # Given attempts are exact; the link's are tried for at least the least patience too.
    data = Map.merge(request, %{attempts: attempts, first_sent_at: Retry.patience_from(opts), wait_ms: wait, sent: 0, other: nil})
    {:ok, {:waiting, 1}, data}
  end

  @impl true
  def handle_event(:enter, _old, {:waiting, n}, data) do
    data.send.(message(data))
    {:keep_state, %{data | sent: n}, [{:state_timeout, data.wait_ms, :resend}]}
  end

  def handle_event(:state_timeout, :resend, {:waiting, n}, data) do
    cond do
      n < data.attempts or Retry.patient?(data.first_sent_at) -> {:next_state, {:waiting, n + 1}, data}
      # Answered only with another value: that is what it keeps.
      data.other != nil -> refused(data, elem(data.other, 0))
      true -> finish(data, {:error, %ParamError{param: data.name, vehicle: data.vehicle, result: :timeout, asked: data.value, attempts: n}})
    end
  end

  def handle_event(:info, {:param, %M.ParamValue{param_value: kept} = v}, _state, %{value: nil} = data), do: finish(data, {:ok, answer(data, v, kept)})

  # Compared as the float32 the vehicle keeps. Another value may be a copy
  # of an older PARAM_VALUE of that name come late (a list being fetched, a
  # duplicate on the radio): it is noted, and the set goes on as if
  # unanswered — sent again when its wait is over. The same other value in
  # answer to a later sending is the vehicle's refusal.
  def handle_event(:info, {:param, %M.ParamValue{param_value: kept} = v}, {:waiting, n}, data) do
    cond do
      same?(kept, data.value) -> finish(data, {:ok, answer(data, v, kept)})
      match?({_other, earlier} when earlier < n, data.other) and same?(kept, elem(data.other, 0)) -> refused(data, kept)
      true -> {:keep_state, %{data | other: {kept, n}}}
    end
  end

  defp refused(data, kept),
    do: finish(data, {:error, %ParamError{param: data.name, vehicle: data.vehicle, result: :refused, asked: data.value, kept: kept, attempts: data.sent}})

  # NaN and infinities (atoms from the codec) are no value asked for.
  defp same?(a, b) when is_number(a) and is_number(b), do: <<a::float-32>> == <<b::float-32>>
  defp same?(_a, _b), do: false

  @doc """
  A PARAM_VALUE's value as its MAV_PARAM_TYPE says (ArduPilot sends every
  value as a float, cast from its type): an integer for the integer types
  (1..8), a float otherwise.

      iex> Dolphin.Vehicles.ParamProtocol.typed(3.0, 2)
      3
      iex> Dolphin.Vehicles.ParamProtocol.typed(0.25, 9)
      0.25
  """
  @spec typed(number(), non_neg_integer()) :: number()
  def typed(value, type) when type in 1..8 and is_number(value), do: round(value)
  def typed(value, _type), do: value

  @doc """
  A parameter's value as a person reads and writes it (the console, `mix
  dolphin.param`, a saved file): whole numbers without a fraction, a
  float of a REAL32 parameter to six decimals at most (its float32 noise
  not shown), a very small or very large one in exponent form.

      iex> Dolphin.Vehicles.ParamProtocol.show(1000.0)
      "1000"
      iex> Dolphin.Vehicles.ParamProtocol.show(0.10000000149011612)
      "0.1"
      iex> Dolphin.Vehicles.ParamProtocol.show(-6)
      "-6"
      iex> Dolphin.Vehicles.ParamProtocol.show(2.5e-6)
      "2.5e-6"
  """
  @spec show(number()) :: String.t()
  def show(value) when is_integer(value), do: Integer.to_string(value)
  def show(value) when is_float(value) and value == trunc(value) and abs(value) < 1.0e15, do: Integer.to_string(trunc(value))
  def show(value) when is_float(value) and abs(value) >= 1.0e-4 and abs(value) < 1.0e15, do: :erlang.float_to_binary(value, [{:decimals, 6}, :compact])
  def show(value) when is_float(value), do: :erlang.float_to_binary(value, [:short])

  @doc """
  Parameters (`%{name, value}`) as lines of a listing: names in a column,
  values (`show/1`) after them.

      iex> Dolphin.Vehicles.ParamProtocol.listing([%{name: "RTL_ALT", value: 1500.0}, %{name: "FENCE_ENABLE", value: 0}])
      ["RTL_ALT       1500", "FENCE_ENABLE  0"]
  """
  @spec listing([%{name: String.t(), value: number()}]) :: [String.t()]
  def listing(params) do
    width = params |> Enum.map(&String.length(&1.name)) |> Enum.max(fn -> 0 end)
    Enum.map(params, &(String.pad_trailing(&1.name, width) <> "  " <> show(&1.value)))
  end

  # Typed (`typed/2`) when the caller asked for it.
  defp answer(%{typed: true}, v, kept), do: typed(kept, v.param_type)
  defp answer(_data, _v, kept), do: kept

  defp finish(data, reply) do
    if data.reply_to, do: :gen_statem.reply(data.reply_to, reply)
    {:stop, :normal, data}
  end

  defp message(%{value: nil} = data), do: %M.ParamRequestRead{target_system: data.sysid, target_component: 1, param_id: data.name, param_index: -1}
  defp message(data), do: %M.ParamSet{target_system: data.sysid, target_component: 1, param_id: data.name, param_value: data.value * 1.0, param_type: @real32}
end
