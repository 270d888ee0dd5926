defmodule Dolphin.MAVLink do
  @moduledoc """
  A MAVLink 1/2 codec, pure (no processes), generated at compile time from the
  official dialect XML.

  The pieces:

    * `Dolphin.MAVLink.Ardupilotmega` — the compiled `ardupilotmega` dialect: one
      struct module per message (`Dolphin.MAVLink.Ardupilotmega.Heartbeat`, ...),
      message look-ups, enums by name and value. `Dolphin.MAVLink.Dialect`
      compiles any other dialect the same way.
    * `Dolphin.MAVLink.Frame` — one frame: `decode/3` and `encode/2` (MAVLink 1
      and 2, truncation, signing).
    * `Dolphin.MAVLink.Parser` — a stream of frames from chunks of bytes, with
      resynchronisation after garbage and counters of everything dropped.
    * `Dolphin.MAVLink.Signing` — MAVLink 2 signing and replay protection.
    * `Dolphin.MAVLink.Value` — how field values look (NaN and infinities included).
    * `Dolphin.MAVLink.Record` — frames as JSON lines (the `mavlink.decode` and
      `mavlink.encode` tasks).

  Nothing here refers to the rest of Dolphin.

      iex> alias Dolphin.MAVLink.Ardupilotmega.CommandLong
      iex> bytes = Dolphin.MAVLink.encode(%CommandLong{command: 400, param1: 1.0, target_system: 1}, sysid: 255, compid: 190)
      iex> {:ok, frame, <<>>} = Dolphin.MAVLink.decode(bytes)
      iex> {frame.sysid, frame.message.command, frame.message.param1}
      {255, 400, 1.0}
  """

  alias Dolphin.MAVLink.{Frame, Message}

  # With messages of the user's own, the dialect that decodes them and hands
  # the rest to ArduPilot's.
  @default_dialect if Dolphin.MAVLink.UserDialect.user_messages() == [], do: Dolphin.MAVLink.Ardupilotmega, else: Dolphin.MAVLink.UserDialect

  @doc """
  The dialect used when none is given: `Dolphin.MAVLink.Ardupilotmega`, or
  `Dolphin.MAVLink.UserDialect` when the project has messages of its own.
  """
  @spec default_dialect() :: module()
  def default_dialect, do: @default_dialect

  @doc "Decodes the frame at the start of `bytes` (see `Dolphin.MAVLink.Frame.decode/3`)."
  @spec decode(binary(), module()) :: {:ok, Frame.t(), binary()} | {:more, binary()} | {:error, Frame.error_reason(), binary()}
  def decode(bytes, dialect \\ @default_dialect), do: Frame.decode(bytes, dialect)

  @doc "Encodes a message into a frame (see `Dolphin.MAVLink.Frame.encode/2` for options)."
  @spec encode(Message.t(), [Frame.encode_opt()]) :: binary()
  def encode(message, opts \\ []), do: Frame.encode(message, opts)
end
