defmodule Dolphin.Test.UDPPeer do
  @moduledoc """
  A scripted MAVLink peer on 127.0.0.1 for tests: sends frames as some system id
  to a ground-station port and collects what comes back, decoded.
  """

  alias Dolphin.MAVLink.{Frame, Parser}

  @doc "Opens a UDP socket on 127.0.0.1 (an ephemeral port), owned by the caller."
  def open do
    # A test reads only when it looks for something, and a loaded machine can
    # hold it back for seconds while the ground station sends (its heartbeats
    # at a speed-up's rate): a kernel buffer larger than the default keeps the
    # datagrams that matter from being dropped meanwhile (the kernel caps it at
    # net.core.rmem_max).
    {:ok, socket} = :gen_udp.open(0, [:binary, active: false, ip: {127, 0, 0, 1}, recbuf: 4_194_304])
    socket
  end

  @doc "Sends a message as `sysid`/`compid` to `port` on 127.0.0.1."
  def send_message(socket, port, message, opts \\ []) do
    bytes = Frame.encode(message, Keyword.merge([sysid: 1, compid: 1], opts))
    :ok = :gen_udp.send(socket, {127, 0, 0, 1}, port, bytes)
  end

  @doc "Receives frames until `fun` returns true for one (returned), or fails after `timeout` ms."
  def receive_until(socket, fun, timeout \\ 2_000) do
    deadline = System.monotonic_time(:millisecond) + timeout
    loop(socket, fun, deadline)
  end

  defp loop(socket, fun, deadline) do
    left = deadline - System.monotonic_time(:millisecond)

    if left <= 0 do
      raise ExUnit.AssertionError, message: "the peer received no matching frame in time"
    else
      case :gen_udp.recv(socket, 0, left) do
        {:ok, {_ip, _port, datagram}} ->
          {frames, _} = Parser.feed(Parser.new(), datagram)
          Enum.find(frames, fun) || loop(socket, fun, deadline)

        {:error, :timeout} ->
          raise ExUnit.AssertionError, message: "the peer received no matching frame in time"
      end
    end
  end
end
