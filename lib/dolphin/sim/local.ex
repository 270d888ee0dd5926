defmodule Dolphin.Sim.Local do
  @moduledoc """
  A simulated fleet on a local link, as the command-line tools start it
  (`mix dolphin.run --sim N`, `mix dolphin.console --sim N`, `--sim
  copter:2,boat:1,sub:3`): a ground-station link on 127.0.0.1, N simulated
  ArduCopters (or those airframes, system ids in that order) with cameras
  sending to it at the clock's speed-up, and a wait until the fleet knows
  them all.
  """

  @typedoc "What `start/2` started: the link, its port and the simulated system ids."
  @type t :: %{link: pid(), port: :inet.port_number(), sysids: [byte()]}

  @doc """
  Starts `count` simulated vehicles (or the groups of `groups/1`) on a new
  local link. Options: `:seed`, `:first_sysid` (default 1), `:world` (what
  their sensors sense: a `Dolphin.Sim.World` or a world file's path),
  `:sensors` (more sensors by system id, a fleet file's), and the link's options (`:tlog`, `:forward`). Returns once the fleet knows every
  vehicle (or after 10 s of real time), or an error saying what failed.
  """
  @spec start(pos_integer() | [{atom(), pos_integer()}], keyword()) :: {:ok, t()} | {:error, Dolphin.Sim.Error.t()}
  def start(fleet, opts \\ [])
  def start(count, opts) when is_integer(count), do: start([copter: count], opts)

  def start(fleet, opts) when is_list(fleet) do
    name = {:dolphin_local_sim, System.unique_integer([:positive])}
    fleet = groups(fleet)
    count = fleet |> Enum.map(&elem(&1, 1)) |> Enum.sum()
    {seed, opts} = Keyword.pop(opts, :seed, 1)
    {first, opts} = Keyword.pop(opts, :first_sysid, 1)
    {home, opts} = Keyword.pop(opts, :home)
    {carried, opts} = Keyword.pop(opts, :sensors, %{})
    {world, link_opts} = Keyword.pop(opts, :world)

    case Dolphin.Link.connect("udpin:127.0.0.1:0", [name: name] ++ link_opts) do
      {:ok, link} ->
        port = Dolphin.Link.Connection.port(name)
        # Camera drones: every simulated vehicle carries a camera (component 100).
        # They boot as ArduCopter does: 2 s of MAV_STATE BOOT refusing uploads.
        sim_opts = [gcs: {{127, 0, 0, 1}, port}, speedup: Dolphin.Clock.speedup(), seed: seed, camera: true, boot_ms: 2_000] ++ if(world, do: [world: world], else: [])

        case start_groups(fleet, first, count, home, carried, sim_opts) do
          {:ok, sysids} ->
            await_fleet(sysids)
            {:ok, %{link: link, port: port, sysids: sysids}}

          {:error, e} ->
            Dolphin.Link.disconnect(link)
            {:error, %{e | message: "--sim: " <> e.message}}
        end

      {:error, e} ->
        {:error, %Dolphin.Sim.Error{reason: :start_failed, message: "--sim: cannot open a local link: #{Exception.message(e)}"}}
    end
  end

  # One Dolphin.Sim.start per airframe, the homes of the whole fleet spread
  # once (a submarine's at the surface, sea level), system ids in order.
  defp start_groups(fleet, first, count, home, carried, sim_opts) do
    around = if home, do: [home: home], else: []
    homes = Dolphin.Sim.homes(count, around)
    # The fleet's charging station is at the centre its homes are spread
    # around, as when one start spreads them all (Dolphin.Sim.start/1).
    [charger] = Dolphin.Sim.homes(1, around)

    fleet
    |> Enum.reduce_while({:ok, [], first, homes}, fn {airframe, n, sensors}, {:ok, started, next, homes} ->
      {mine, rest} = Enum.split(homes, n)
      mine = if Dolphin.Airframe.heights(airframe) == :depth, do: Enum.map(mine, &%{&1 | alt: 0.0}), else: mine

      # A group's sensors, and those the fleet file gives each of its vehicles.
      sensors = Map.new(next..(next + n - 1), &{&1, Enum.uniq(sensors ++ Map.get(carried, &1, []))})

      case Dolphin.Sim.start(sim_opts ++ [count: n, first_sysid: next, homes: mine, charger: charger, airframe: airframe, sensors: sensors]) do
        {:ok, sysids} -> {:cont, {:ok, started ++ sysids, next + n, rest}}
        {:error, e} -> {:halt, {:error, e, started}}
      end
    end)
    |> case do
      {:ok, sysids, _, _} ->
        {:ok, sysids}

      {:error, e, started} ->
        Enum.each(started, &Dolphin.Sim.stop/1)
        {:error, e}
    end
  rescue
    e in ArgumentError -> {:error, %Dolphin.Sim.Error{reason: :bad_option, message: Exception.message(e)}}
  end

  @doc """
  A fleet as `--sim` gives it — a number of copters, or `{airframe, count}`
  and `{airframe, count, sensors}` groups — as `{airframe, count, sensors}`
  groups.

      iex> Dolphin.Sim.Local.groups([copter: 2, boat: 1])
      [{:copter, 2, []}, {:boat, 1, []}]
      iex> Dolphin.Sim.Local.groups(3)
      [{:copter, 3, []}]
  """
  @spec groups(pos_integer() | [{atom(), pos_integer()} | {atom(), pos_integer(), [atom()]}]) :: [{atom(), pos_integer(), [atom()]}]
  def groups(n) when is_integer(n), do: [{:copter, n, []}]
  def groups(fleet) when is_list(fleet), do: Enum.map(fleet, fn {a, n} -> {a, n, []}; {_, _, _} = g -> g end)

  @doc """
  Stops what `start/2` started; the ground station forgets the vehicles too (a
  later fleet in the same VM starts from system id 1 again).
  """
  @spec stop(t()) :: :ok
  def stop(%{link: link, sysids: sysids}) do
    Enum.each(sysids, &Dolphin.Sim.stop/1)

    Enum.each(sysids, &Dolphin.Vehicles.forget/1)

    Dolphin.Link.disconnect(link)
    :ok
  end

  # Simulated vehicles announce themselves within a heartbeat, and have
  # booted (past MAV_STATE BOOT) 2 s of clock time later.
  defp await_fleet(sysids, tries \\ 200 + div(Dolphin.Clock.to_real_ms(2_000), 50)) do
    if tries > 0 and not Enum.all?(sysids, &Dolphin.Vehicles.ready?/1) do
      Process.sleep(50)
      await_fleet(sysids, tries - 1)
    end
  end
end
