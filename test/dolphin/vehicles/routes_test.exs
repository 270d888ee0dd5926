defmodule Dolphin.Vehicles.RoutesTest do
  # Routes to vehicles this node has no process of, kept by their router.
  use ExUnit.Case, async: false

  alias Dolphin.Test.Wait
  alias Dolphin.Vehicles.Routes

  # A router as the cluster's mirror is one: it writes routes and answers
  # the vehicles layer's calls about them.
  defp router(test) do
    spawn_link(fn -> serve(test) end)
  end

  defp serve(test) do
    receive do
      {:put, id, pid} ->
        Routes.put(id, pid)
        send(test, {:put, id})
        serve(test)

      {:"$gen_call", from, {:reroute, id, dead}} ->
        send(test, {:asked, :reroute, id, dead})
        GenServer.reply(from, Routes.get(id))
        serve(test)

      {:"$gen_call", from, {:forget, id}} ->
        Routes.delete(id)
        send(test, {:asked, :forget, id})
        GenServer.reply(from, :ok)
        serve(test)

      :stop ->
        :ok
    end
  end

  test "Dolphin.Vehicles finds a routed vehicle, asks its router to reroute and to forget it" do
    id = 240
    target = spawn(fn -> Process.sleep(:infinity) end)
    r = router(self())
    send(r, {:put, id, target})
    assert_receive {:put, ^id}

    assert Dolphin.Vehicles.whereis(id) == target
    assert Routes.reroute(id, target) == target
    assert_receive {:asked, :reroute, ^id, ^target}

    assert Dolphin.Vehicles.forget(id) == :ok
    assert_receive {:asked, :forget, ^id}
    assert Dolphin.Vehicles.whereis(id) == nil
    send(r, :stop)
  end

  test "a router that ends takes its routes with it" do
    id = 241
    target = spawn(fn -> Process.sleep(:infinity) end)
    test = self()
    r = spawn(fn -> serve(test) end)
    send(r, {:put, id, target})
    Wait.until(fn -> Routes.get(id) == target end, 30_000, fn -> "the route put" end)

    send(r, :stop)
    Wait.until(fn -> Routes.get(id) == nil end, 30_000, fn -> "the route of a router that ended still there" end)
    assert Routes.reroute(id, target) == nil
    assert Routes.forget(id) == :ok
  end
end
