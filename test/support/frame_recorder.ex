defmodule Dolphin.Test.FrameRecorder do
  @moduledoc """
  Records what a ground-station link carries, for tests that compare how two
  autopilots behave: a UDP socket on 127.0.0.1 that a link forwards all its
  traffic to (`Dolphin.Link.connect(..., forward: [Dolphin.Test.FrameRecorder.endpoint(r)])`),
  decoding every frame and stamping it with the sending vehicle's own time
  (`time_boot_ms` of its latest GLOBAL_POSITION_INT or SYSTEM_TIME), so that
  timings are read in the vehicle's time even when it runs slower than asked.

      {:ok, r} = Dolphin.Test.FrameRecorder.start_link()
      # ... fly ...
      frames = Dolphin.Test.FrameRecorder.frames(r)   # [{vehicle_ms, sysid, message}]
  """

  use GenServer

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.MAVLink.Parser

  def start_link(opts \\ []), do: GenServer.start_link(__MODULE__, opts)

  @doc "The `udpout` endpoint to forward a link's traffic to."
  def endpoint(pid), do: "udpout:127.0.0.1:#{GenServer.call(pid, :port)}"

  @doc "Every frame a vehicle sent, oldest first: `{vehicle_ms, sysid, message}`."
  def frames(pid), do: GenServer.call(pid, :frames) |> Enum.reverse()

  @impl true
  def init(_opts) do
    {:ok, socket} = :gen_udp.open(0, [:binary, active: true, ip: {127, 0, 0, 1}, recbuf: 1_048_576])
    {:ok, %{socket: socket, parser: Parser.new(), clocks: %{}, frames: []}}
  end

  @impl true
  def handle_call(:port, _from, s), do: {:reply, elem(:inet.port(s.socket), 1), s}
  def handle_call(:frames, _from, s), do: {:reply, s.frames, s}

  @impl true
  def handle_info({:udp, _socket, _ip, _port, data}, s) do
    {frames, parser} = Parser.feed(s.parser, data)
    {:noreply, Enum.reduce(frames, %{s | parser: parser}, &record/2)}
  end

  # The ground station's own frames (system 255) are not the vehicles'.
  defp record(%{sysid: 255}, s), do: s

  defp record(%{sysid: sysid, message: message}, s) do
    clocks =
      case message do
        %M.GlobalPositionInt{time_boot_ms: t} -> Map.put(s.clocks, sysid, t)
        %M.SystemTime{time_boot_ms: t} -> Map.put(s.clocks, sysid, t)
        _ -> s.clocks
      end

    %{s | clocks: clocks, frames: [{Map.get(clocks, sysid), sysid, message} | s.frames]}
  end
end
