defmodule Dolphin.Test.Backend do
  @moduledoc """
  The two kinds of vehicles a test can fly, started alike: the built-in
  simulator (`:sim`, `Dolphin.Sim.Local`) and ArduCopter SITL (`:sitl`,
  `Dolphin.SITL`), each on its own local link, at the clock's speed-up.
  `start/3` stops them when the test ends.

  SITL tests run at `speedup(:sitl)`: 10 by default, or `$DOLPHIN_SITL_SPEEDUP`.
  Measured on a 2-core machine, an instance at 10× uses about a third of a
  core, so that two or three keep pace beside the ground station.
  """

  import ExUnit.Callbacks, only: [on_exit: 1]

  @sitl_speedup 10

  @doc "The speed-up a backend's tests run at."
  def speedup(:sim), do: 25
  def speedup(:sitl), do: (System.get_env("DOLPHIN_SITL_SPEEDUP") || "#{@sitl_speedup}") |> String.to_integer()

  @doc """
  Sets the clock to the backend's speed-up and starts `count` vehicles;
  returns their system ids. Options go to the backend (`:forward`, `:tlog`,
  `:params` for SITL, `:seed` for the simulator). `stop/1` stops them sooner
  than the end of the test.
  """
  def start(backend, count, opts \\ []) do
    Dolphin.Clock.set_speedup(Keyword.get(opts, :speedup, speedup(backend)))
    opts = Keyword.delete(opts, :speedup)

    {:ok, fleet} =
      case backend do
        :sim -> Dolphin.Sim.Local.start(count, Keyword.take(opts, [:seed, :tlog, :forward]))
        :sitl -> Dolphin.SITL.start(count, opts)
      end

    Process.put({__MODULE__, hd(fleet.sysids)}, {backend, fleet})
    instance = Dolphin.Instance.current()
    on_exit(fn -> Dolphin.Test.Instance.within(instance, fn -> stop(backend, fleet) end) end)
    fleet.sysids
  end

  @doc "A vehicle's home, once it reports one (ArduCopter: once its EKF has an origin)."
  def home(id) do
    Dolphin.Test.Wait.until(fn -> match?({:ok, %{home: %{}}}, Dolphin.Vehicles.state(id)) end, 2_000, fn -> "home of vehicle #{id}" end)
    {:ok, %{home: h}} = Dolphin.Vehicles.state(id)
    Dolphin.Geo.location(h.lat, h.lon, h.alt)
  end

  @doc "What the backend's `start` returned, for the vehicles whose first id is `first`."
  def fleet(first), do: Process.get({__MODULE__, first}) |> elem(1)

  @doc "Stops the vehicles `start/3` returned (their picks are released with them)."
  def stop([first | _] = sysids) do
    {backend, fleet} = Process.delete({__MODULE__, first})
    _ = Dolphin.Fleet.release(Dolphin.Instance.names().fleet, self(), sysids)
    stop(backend, fleet)
  end

  defp stop(backend, fleet) do
    case backend do
      :sim -> Dolphin.Sim.Local.stop(fleet)
      :sitl -> Dolphin.SITL.stop(fleet)
    end

    Dolphin.Clock.set_speedup(1)
  end
end
