defmodule Dolphin.Test.GroundStation do
  @moduledoc """
  A ground-station link on 127.0.0.1 for tests that fly simulated vehicles,
  and the clean-up after them: simulated vehicles stopped, the ground station's
  vehicles forgotten (the next test's start at system id 1 again), the link
  closed, the clock back to real time.
  """

  import ExUnit.Callbacks, only: [on_exit: 1]

  alias Dolphin.{Link, Vehicles}
  alias Dolphin.Link.Connection

  # The names of the links open/1 opens begin so (forget_vehicles/0 finds them by it).
  @link_prefix "test-gcs-"

  @doc "Opens a link (closed when the test ends; `opts` as `Dolphin.Link.connect/2`'s) and returns the port simulated vehicles send to."
  def open(opts \\ []) do
    name = @link_prefix <> "#{System.unique_integer([:positive])}"
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", [name: name] ++ opts)
    instance = Dolphin.Instance.current()

    on_exit(fn ->
      Dolphin.Test.Instance.within(instance, fn ->
        forget_vehicles()
        Link.disconnect(link)
      end)
    end)

    Connection.port(name)
  end

  # Ports for links opened later are taken below the system's ephemeral
  # range (32768 and up on Linux): a port the system handed out and took
  # back would be handed out again, to another test's socket, which would
  # then hear what was meant for this one's link.
  @later_ports 20_000..32_767

  @doc """
  A UDP port on 127.0.0.1 nobody listens on now (for a link a test opens
  later), outside the range the system hands ephemeral ports from, and a
  different one at every call in this BEAM.
  """
  def free_udp_port do
    # Two BEAMs (the suite's parts) start far apart in the range.
    offset = :erlang.phash2(System.pid(), Enum.count(@later_ports))
    n = System.unique_integer([:positive, :monotonic])
    port = @later_ports.first + rem(offset + n, Enum.count(@later_ports))

    case :gen_udp.open(port, ip: {127, 0, 0, 1}) do
      {:ok, socket} ->
        :gen_udp.close(socket)
        port

      {:error, :eaddrinuse} ->
        free_udp_port()
    end
  end

  @doc """
  Stops the simulated vehicles and forgets every vehicle the ground station
  knew, once the links opened by `open/1` have read all the vehicles sent.
  """
  def forget_vehicles do
    Dolphin.Sim.stop()
    Enum.each(opened_links(), &drain/1)
    Enum.each(Vehicles.list(), &Vehicles.forget/1)
    Dolphin.Clock.set_speedup(1)
  end

  # What stopped vehicles sent may still wait in a link's socket: read after
  # they were forgotten, it would discover one again at an address nobody
  # answers from any more, and the next vehicle given its system id, heard
  # from another address, would be a path of that ghost, unused until the
  # ghost's address has been quiet for 10 s of real time
  # (Dolphin.Vehicles.Paths: the ghost's own unique id never comes). A datagram sent to the link
  # now is read after all of that: once the link has counted its bytes (no
  # frame begins with them), what came before it has been delivered.
  @marker <<0, 0, 0, 0, 0, 0, 0, 0>>

  defp drain(name) do
    port = Connection.port(name)
    skipped = fn -> Connection.info(name).stats.bytes_skipped end
    before = skipped.()
    {:ok, socket} = :gen_udp.open(0, ip: {127, 0, 0, 1})

    try do
      :ok = :gen_udp.send(socket, {127, 0, 0, 1}, port, @marker)
      Dolphin.Test.Wait.until(fn -> skipped.() >= before + byte_size(@marker) end, 250, fn -> "(link #{name} reading what came before a marker datagram)" end)
    after
      :gen_udp.close(socket)
    end
  catch
    # The test closed that link itself meanwhile: nothing left to read.
    :exit, _ -> :ok
  end

  defp opened_links do
    Dolphin.Instance.names().registry
    |> Registry.select([{{{:link, :"$1"}, :_, :_}, [], [:"$1"]}])
    |> Enum.filter(&(is_binary(&1) and String.starts_with?(&1, @link_prefix)))
  end
end
