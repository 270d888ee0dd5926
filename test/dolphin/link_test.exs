defmodule Dolphin.LinkTest do
  # Application configuration of links. Starts and stops links: not async.
  use ExUnit.Case, async: false

  alias Dolphin.Link
  alias Dolphin.Link.Connection

  setup do
    on_exit(fn ->
      Application.delete_env(:dolphin, :links)
      Application.delete_env(:dolphin, :gcs_sysid)
      for {_, pid, _, _} <- DynamicSupervisor.which_children(Dolphin.Link.Supervisor), do: DynamicSupervisor.terminate_child(Dolphin.Link.Supervisor, pid)
    end)
  end

  test "links from the configuration, several at once, with their options" do
    Application.put_env(:dolphin, :links, ["udpin:127.0.0.1:0", {"udpout:127.0.0.1:9", name: "configured-out"}])
    Application.put_env(:dolphin, :gcs_sysid, 250)
    assert :ok = Link.connect_configured()
    assert is_integer(Connection.port("udpin:127.0.0.1:0"))
    assert %{connected: true} = Connection.info("configured-out")
    assert :sys.get_state(GenServer.whereis({:via, Registry, {Dolphin.Registry, {:link, "configured-out"}}})).gcs == {250, 190}
  end

  test "a bad configured endpoint says which and why" do
    Application.put_env(:dolphin, :links, ["udpin:127.0.0.1"])
    assert_raise ArgumentError, ~r/config :dolphin, links: endpoint "udpin:127.0.0.1": expected KIND:HOST:PORT/, fn -> Link.connect_configured() end
    # As the application's child: the start fails with the reason.
    assert {:error, "config :dolphin, links: endpoint" <> _} = Link.start_configured()
    assert Link.default_endpoint() == "udpin:0.0.0.0:14550"
  end
end
