defmodule Dolphin.MAVLink.Signing do
  @moduledoc """
  MAVLink 2 message signing for one link: signing outgoing frames and checking
  incoming ones, as the MAVLink signing specification describes.

  A signature is the first 6 bytes of SHA-256(secret key ‖ frame from the magic
  byte through the link id and the 48-bit timestamp). Timestamps count 10 µs
  units since 2015-01-01 00:00:00 UTC.

  State (pure data; a link process keeps it):

    * `key`: the 32-byte secret;
    * `link_id`: our link id, written into frames we sign;
    * `timestamp`: the link's local timestamp: the latest of the clock, every
      timestamp we signed with and every accepted incoming timestamp;
    * `streams`: the last accepted timestamp per `{sysid, compid, link_id}`;
    * `unsigned`: what to do with unsigned frames: `:reject` (the default, as
      the spec wants of a system with signing on), `:accept`, or a function
      `frame -> boolean` (the spec lets a system accept, say, RADIO_STATUS
      unsigned while demanding signatures on everything else).

  An incoming signed frame is accepted when its signature matches, and its
  timestamp is newer than the last one of its stream, or, for a stream not seen
  before, no more than one minute older than the local timestamp.

      iex> alias Dolphin.MAVLink.{Frame, Signing}
      iex> signer = Signing.new(key: :binary.copy(<<7>>, 32), link_id: 3)
      iex> {bytes, _signer} = Signing.encode(signer, %Dolphin.MAVLink.Ardupilotmega.Heartbeat{type: 6}, sysid: 255)
      iex> {:ok, frame, <<>>} = Frame.decode(bytes, Dolphin.MAVLink.Ardupilotmega)
      iex> {:ok, _checker} = Signing.verify(Signing.new(key: :binary.copy(<<7>>, 32)), frame)
      iex> {:error, :old_timestamp, _} = Signing.verify(Signing.new(key: :binary.copy(<<7>>, 32), timestamp: Signing.now() + 7_000_000), frame)
      iex> frame.signature.link_id
      3
  """

  alias Dolphin.MAVLink.{Frame, Message}

  # 2015-01-01T00:00:00Z in Unix microseconds.
  @epoch_us 1_420_070_400_000_000
  # A new stream may start at most one minute (in 10 µs units) behind the local timestamp.
  @new_stream_window 6_000_000

  defstruct key: nil, link_id: 0, timestamp: 0, streams: %{}, unsigned: :reject

  @type unsigned_policy :: :accept | :reject | (Frame.t() -> boolean())

  @type t :: %__MODULE__{
          key: <<_::256>>,
          link_id: byte(),
          timestamp: non_neg_integer(),
          streams: %{optional({byte(), byte(), byte()}) => non_neg_integer()},
          unsigned: unsigned_policy()
        }

  @type reject_reason :: :bad_signature | :old_timestamp | :unsigned

  @doc """
  A signing state. Options: `:key` (32 bytes, or 64 hex digits; required),
  `:link_id` (default 0), `:unsigned` (default `:reject`), `:timestamp` (the
  starting local timestamp, default the clock, `now/0`: a new stream more than
  a minute older than that is refused as a replay; a reader of recorded
  traffic, whose timestamps are in the past, passes 0).
  """
  @spec new(keyword()) :: t()
  def new(opts) do
    %__MODULE__{
      key: key!(Keyword.fetch!(opts, :key)),
      link_id: Keyword.get(opts, :link_id, 0),
      timestamp: Keyword.get_lazy(opts, :timestamp, &now/0),
      unsigned: unsigned!(Keyword.get(opts, :unsigned, :reject))
    }
  end

  @doc "A 32-byte signing key from its 64 hex digits (either case)."
  @spec decode_key(String.t()) :: {:ok, <<_::256>>} | :error
  def decode_key(hex) when is_binary(hex) and byte_size(hex) == 64 do
    case Base.decode16(hex, case: :mixed) do
      {:ok, key} -> {:ok, key}
      :error -> :error
    end
  end

  def decode_key(_other), do: :error

  defp key!(<<_::binary-32>> = key), do: key

  defp key!(hex) when is_binary(hex) and byte_size(hex) == 64 do
    case decode_key(hex) do
      {:ok, key} -> key
      :error -> raise ArgumentError, "signing key is not hexadecimal: #{inspect(hex)}"
    end
  end

  defp key!(other), do: raise(ArgumentError, "signing key must be 32 bytes or 64 hex digits, got: #{inspect(other)}")

  defp unsigned!(policy) when policy in [:accept, :reject] or is_function(policy, 1), do: policy

  defp unsigned!(other),
    do: raise(ArgumentError, "unsigned-frame policy must be :accept, :reject or a 1-arity function, got: #{inspect(other)}")

  @doc "The current time as a signing timestamp (10 µs units since 2015-01-01)."
  @spec now() :: non_neg_integer()
  def now, do: div(System.os_time(:microsecond) - @epoch_us, 10)

  @doc """
  Encodes and signs a message (MAVLink 2), with a timestamp newer than any the
  link used or saw. Takes `Dolphin.MAVLink.Frame.encode/2`'s header options and
  `:now` (the clock, default `now/0`).
  """
  @spec encode(t(), Message.t(), keyword()) :: {binary(), t()}
  def encode(%__MODULE__{} = state, message, opts \\ []) do
    {now, opts} = Keyword.pop_lazy(opts, :now, &now/0)
    timestamp = max(state.timestamp + 1, now)
    signing = %{key: state.key, link_id: state.link_id, timestamp: timestamp}
    {Frame.encode(message, Keyword.merge(opts, version: 2, signing: signing)), %{state | timestamp: timestamp}}
  end

  @doc """
  Checks an incoming frame (with no signing state, `nil`, every frame passes
  unchecked). Returns the updated state, or the reason to drop it:
  `:bad_signature`, `:old_timestamp` (a replay, or a new stream too far in the
  past) or `:unsigned` (an unsigned frame the policy refuses).
  """
  @spec verify(t() | nil, Frame.t()) :: {:ok, t() | nil} | {:error, reject_reason(), t()}
  def verify(nil, _frame), do: {:ok, nil}

  def verify(%__MODULE__{} = state, %Frame{signature: nil} = frame) do
    accept? =
      case state.unsigned do
        :accept -> true
        :reject -> false
        fun -> fun.(frame) == true
      end

    if accept?, do: {:ok, state}, else: {:error, :unsigned, state}
  end

  def verify(%__MODULE__{} = state, %Frame{signature: sig, raw: raw} = frame) do
    signed_part = binary_part(raw, 0, byte_size(raw) - 6)
    <<expected::binary-6, _::binary>> = :crypto.hash(:sha256, [state.key, signed_part])
    stream = {frame.sysid, frame.compid, sig.link_id}

    cond do
      expected != sig.signature ->
        {:error, :bad_signature, state}

      stale?(Map.fetch(state.streams, stream), sig.timestamp, state.timestamp) ->
        {:error, :old_timestamp, state}

      true ->
        {:ok,
         %{
           state
           | streams: Map.put(state.streams, stream, sig.timestamp),
             timestamp: max(state.timestamp, sig.timestamp)
         }}
    end
  end

  @doc false
  # verify/2 for a reader that keeps its signing state in a `signing` field
  # (Dolphin.MAVLink.Parser, Dolphin.MAVLink.Tlog): the reader comes back updated.
  @spec verify_for(holder, Frame.t()) :: {:ok, holder} | {:error, reject_reason(), holder}
        when holder: %{:signing => t() | nil, optional(atom()) => term()}
  def verify_for(%{signing: signing} = holder, frame) do
    case verify(signing, frame) do
      {:ok, signing} -> {:ok, %{holder | signing: signing}}
      {:error, reason, signing} -> {:error, reason, %{holder | signing: signing}}
    end
  end

  defp stale?({:ok, last}, timestamp, _local), do: timestamp <= last
  defp stale?(:error, timestamp, local), do: timestamp + @new_stream_window < local

  @doc "Moves the local timestamp forward to the clock (call it now and then on a live link)."
  @spec tick(t(), non_neg_integer()) :: t()
  def tick(%__MODULE__{} = state, now \\ now()), do: %{state | timestamp: max(state.timestamp, now)}
end
