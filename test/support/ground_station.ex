defmodule Dolphin.Test.GroundStation do
  @moduledoc """
  A ground-station link on 127.0.0.1 for tests that fly simulated vehicles,
  and the clean-up after them: simulated vehicles stopped, the ground station's
  vehicles forgotten (the next test's start at system id 1 again), the link
  closed, the clock back to real time.
  """

  import ExUnit.Callbacks, only: [on_exit: 1]

  alias Dolphin.{Link, Vehicles}

  @doc "Opens a link (closed when the test ends; `opts` as `Dolphin.Link.connect/2`'s) and returns the port simulated vehicles send to."
  def open(opts \\ []) do
    name = "test-gcs-#{System.unique_integer([:positive])}"
    {:ok, link} = Link.connect("udpin:127.0.0.1:0", [name: name] ++ opts)
    instance = Dolphin.Instance.current()

    on_exit(fn ->
      Dolphin.Test.Instance.within(instance, fn ->
        forget_vehicles()
        Link.disconnect(link)
      end)
    end)

    Dolphin.Link.Connection.port(name)
  end

  @doc "A UDP port on 127.0.0.1 nobody listens on now (for a link a test opens later)."
  def free_udp_port do
    {:ok, socket} = :gen_udp.open(0, ip: {127, 0, 0, 1})
    {:ok, port} = :inet.port(socket)
    :gen_udp.close(socket)
    port
  end

  @doc "Stops the simulated vehicles and forgets every vehicle the ground station knew."
  def forget_vehicles do
    Dolphin.Sim.stop()
    Enum.each(Vehicles.list(), &Vehicles.forget/1)
    Dolphin.Clock.set_speedup(1)
  end
end
