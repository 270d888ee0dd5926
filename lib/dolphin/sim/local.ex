defmodule Dolphin.Sim.Local do
  @moduledoc """
  A simulated fleet on a local link, as the command-line tools start it
  (`mix dolphin.run --sim N`, `mix dolphin.console --sim N`, `--sim
  copter:2,boat:1,sub:3`): a ground-station link on 127.0.0.1, N simulated
  ArduCopters (or those airframes, system ids in that order) with cameras
  sending to it at the clock's speed-up, and a wait until the fleet knows
  them all.
  """

  @typedoc """
  What `start/2` started: the vehicles as the ground station names them
  (`sysids`: system ids, and `"SYSID@simK"` beyond the first network), and
  each network's number, link, port and its vehicles' system ids; `link` and
  `port` are the first network's.
  """
  @type t :: %{
          link: pid(),
          port: :inet.port_number(),
          sysids: [Dolphin.Vehicles.Id.t()],
          networks: [%{number: pos_integer(), name: String.t() | nil, link: pid(), port: :inet.port_number(), sysids: [byte()]}]
        }

  # A network's system ids: 1..254 (255 is the ground station's).
  @network_size 254
  @max_networks 64

  @doc "The most vehicles `start/2` runs: #{@max_networks} networks of #{@network_size}."
  @spec max_vehicles() :: pos_integer()
  def max_vehicles, do: @network_size * @max_networks

  @doc """
  Starts `count` simulated vehicles (or the groups of `groups/1`) on new
  local links. Options: `:seed`, `:first_sysid` (default 1), `:world` (what
  their sensors sense: a `Dolphin.Sim.World` or a world file's path),
  `:sensors` (more sensors by vehicle id, a fleet file's), `:network_size`
  (the vehicles of a network, default and at most 254), and the links'
  options (`:tlog`, `:forward`). Returns once the fleet knows every
  vehicle (or after 10 s of real time and a little more for a large
  fleet), or an error saying what failed.

  A network holds 254 vehicles (system ids 1..254; fewer with
  `:network_size`): a larger fleet is
  several networks, each a link of its own, the first with system ids
  `first_sysid..254` named by them as always, the K-th (`sim2`, `sim3`,
  ...) with system ids from 1 again, named `"SYSID@simK"`
  (`Dolphin.Vehicles.Id`): `--sim 300` is vehicles 1..254 and `1@sim2`..`46@sim2`.
  """
  @spec start(pos_integer() | [{atom(), pos_integer()}], keyword()) :: {:ok, t()} | {:error, Dolphin.Sim.Error.t()}
  def start(fleet, opts \\ [])
  def start(count, opts) when is_integer(count), do: start([copter: count], opts)

  def start(fleet, opts) when is_list(fleet) do
    fleet = groups(fleet)
    count = fleet |> Enum.map(&elem(&1, 1)) |> Enum.sum()
    {seed, opts} = Keyword.pop(opts, :seed, 1)
    {first, opts} = Keyword.pop(opts, :first_sysid, 1)
    {home, opts} = Keyword.pop(opts, :home)
    {carried, opts} = Keyword.pop(opts, :sensors, %{})
    {size, opts} = Keyword.pop(opts, :network_size, @network_size)
    {world, link_opts} = Keyword.pop(opts, :world)
    # Camera drones: every simulated vehicle carries a camera (component 100).
    # They boot as ArduCopter does: 2 s of MAV_STATE BOOT refusing uploads.
    sim_opts = [speedup: Dolphin.Clock.speedup(), seed: seed, camera: true, boot_ms: 2_000] ++ if(world, do: [world: world], else: [])

    with {:ok, plan} <- plan(fleet, first, count, home, carried, size) do
      # The first network first, and known, so that its vehicles are the
      # ones the plain system ids name; then the others together.
      [first_network | others] = plan

      with {:ok, network} <- start_network(first_network, sim_opts, link_opts),
           :ok <- await_known(network, others),
           {:ok, more} <- start_networks(others, sim_opts, link_opts, [network]) do
        networks = [network | more]
        sim = %{link: network.link, port: network.port, sysids: Enum.flat_map(networks, &ids/1), networks: networks}
        await_fleet(sim.sysids)
        {:ok, sim}
      else
        {:error, e, started} ->
          Enum.each(started, &stop_network/1)
          {:error, %{e | message: "--sim: " <> e.message}}
      end
    end
  end

  # Which vehicle goes where: the fleet's vehicles in order (each with its
  # airframe, its sensors and its home: the whole fleet's homes spread once,
  # a submarine's at the surface) over networks of 254 system ids.
  defp plan(fleet, first, count, home, carried, size) do
    cond do
      not is_integer(size) or size not in 1..@network_size ->
        {:error, %Dolphin.Sim.Error{reason: :bad_option, message: "--sim: a network of #{inspect(size)} vehicles: from 1 to #{@network_size}"}}

      not is_integer(first) or first not in 1..size ->
        {:error, %Dolphin.Sim.Error{reason: :bad_option, message: "--sim: the first system id #{inspect(first)} is not within 1..#{size}"}}

      count > size - first + 1 + size * (@max_networks - 1) ->
        {:error, %Dolphin.Sim.Error{reason: :bad_option, message: "--sim: #{count} vehicles: at most #{size * @max_networks} (#{@max_networks} networks of #{size})"}}

      true ->
        around = if home, do: [home: home], else: []
        homes = Dolphin.Sim.homes(count, around)
        # The fleet's charging station is at the centre its homes are spread
        # around, as when one start spreads them all (Dolphin.Sim.start/1).
        [charger] = Dolphin.Sim.homes(1, around)

        vehicles =
          fleet
          |> Enum.flat_map(fn {airframe, n, sensors} -> List.duplicate({airframe, sensors}, n) end)
          |> Enum.zip(homes)
          |> Enum.map(fn {{airframe, sensors}, home} ->
            {airframe, sensors, if(Dolphin.Airframe.heights(airframe) == :depth, do: %{home | alt: 0.0}, else: home)}
          end)

        {first_network, rest} = Enum.split(vehicles, size - first + 1)

        networks =
          [{1, first, first_network} | rest |> Enum.chunk_every(size) |> Enum.with_index(2) |> Enum.map(fn {vs, k} -> {k, 1, vs} end)]
          |> Enum.map(fn {k, from, vs} -> %{number: k, first: from, vehicles: vs, carried: carried, charger: charger} end)

        {:ok, networks}
    end
  rescue
    e in ArgumentError -> {:error, %Dolphin.Sim.Error{reason: :bad_option, message: Exception.message(e)}}
  end

  defp start_networks([], _sim_opts, _link_opts, _started), do: {:ok, []}

  defp start_networks([network | rest], sim_opts, link_opts, started) do
    case start_network(network, sim_opts, link_opts) do
      {:ok, n} ->
        with {:ok, more} <- start_networks(rest, sim_opts, link_opts, [n | started]), do: {:ok, [n | more]}

      {:error, e, partial} ->
        {:error, e, partial ++ started}
    end
  end

  # One network: its link (named `simK` beyond the first) and its vehicles,
  # one Dolphin.Sim.start per run of one airframe.
  defp start_network(%{number: k, first: first, vehicles: vehicles, carried: carried, charger: charger}, sim_opts, link_opts) do
    # Named for the messages that name a link (unique: two fleets may run in one VM).
    name = "sim#{k}:#{System.unique_integer([:positive])}"
    network = if k > 1, do: "sim#{k}"

    case Dolphin.Link.connect("udpin:127.0.0.1:0", [name: name] ++ if(network, do: [network: network], else: []) ++ link_opts) do
      {:ok, link} ->
        port = Dolphin.Link.Connection.port(name)
        started = %{name: network, link: link, port: port, sysids: [], number: k}

        vehicles
        |> Enum.with_index(first)
        |> Enum.chunk_by(fn {{airframe, sensors, _home}, _sysid} -> {airframe, sensors} end)
        |> Enum.reduce_while({:ok, started}, fn [{{airframe, sensors, _}, from} | _] = run, {:ok, started} ->
          homes = Enum.map(run, fn {{_, _, home}, _} -> home end)
          # A group's sensors, and those the fleet file gives each of its vehicles.
          by_sysid = Map.new(run, fn {_, sysid} -> {sysid, Enum.uniq(sensors ++ Map.get(carried, id(network, sysid), []))} end)
          opts = sim_opts ++ [gcs: {{127, 0, 0, 1}, port}, count: length(run), first_sysid: from, homes: homes, charger: charger, airframe: airframe, sensors: by_sysid]
          opts = if k > 1, do: opts ++ [network: k], else: opts

          case Dolphin.Sim.start(opts) do
            {:ok, _} -> {:cont, {:ok, %{started | sysids: started.sysids ++ Enum.map(run, &elem(&1, 1))}}}
            {:error, e} -> {:halt, {:error, e, [started]}}
          end
        end)

      {:error, e} ->
        {:error, %Dolphin.Sim.Error{reason: :start_failed, message: "cannot open a local link: #{Exception.message(e)}"}, []}
    end
  end

  @doc """
  The names the ground station gives the vehicles of a fleet of `count`
  that `start/2` starts, in order, without starting any (the pre-flight
  check's stand-ins take them).

      iex> Dolphin.Sim.Local.names(3)
      [1, 2, 3]
      iex> Dolphin.Sim.Local.names(256) |> Enum.take(-3)
      [254, "1@sim2", "2@sim2"]
  """
  @spec names(pos_integer(), pos_integer()) :: [Dolphin.Vehicles.Id.t()]
  def names(count, size \\ @network_size) do
    for i <- 0..(count - 1), do: id(if(i < size, do: nil, else: "sim#{div(i, size) + 1}"), rem(i, size) + 1)
  end

  # The ground station's names of a network's vehicles.
  defp ids(%{name: network, sysids: sysids}), do: Enum.map(sysids, &id(network, &1))

  defp id(nil, sysid), do: sysid
  defp id(network, sysid), do: "#{sysid}@#{network}"

  @doc """
  Where the vehicles are, in words: `"[1, 2] on 127.0.0.1:PORT"`; for
  several networks each network's system ids, `"[1..254] on
  127.0.0.1:PORT, [1..46]@sim2 on 127.0.0.1:PORT2"`.
  """
  @spec describe(t()) :: String.t()
  def describe(%{networks: [%{name: nil} = only]}), do: "#{Dolphin.Fleet.VehicleSet.format(only.sysids)} on 127.0.0.1:#{only.port}"

  def describe(%{networks: networks}) do
    Enum.map_join(networks, ", ", fn n -> "[#{range(n.sysids)}]#{if n.name, do: "@#{n.name}"} on 127.0.0.1:#{n.port}" end)
  end

  defp range([only]), do: "#{only}"
  defp range(sysids), do: "#{List.first(sysids)}..#{List.last(sysids)}"

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

  def groups(fleet) when is_list(fleet),
    do:
      Enum.map(fleet, fn
        {a, n} -> {a, n, []}
        {_, _, _} = g -> g
      end)

  @doc """
  Stops what `start/2` started; the ground station forgets the vehicles too (a
  later fleet in the same VM starts from system id 1 again).
  """
  @spec stop(t()) :: :ok
  def stop(%{networks: networks}) do
    Enum.each(networks, &stop_network/1)
    :ok
  end

  defp stop_network(%{link: link, sysids: sysids} = network) do
    # The simulator names a vehicle of a later network {network's number, system id} (Dolphin.Sim).
    key = if network.number > 1, do: &{network.number, &1}, else: & &1
    Enum.each(sysids, &Dolphin.Sim.stop(key.(&1)))
    # The link first: a heartbeat it still held would discover a vehicle
    # just forgotten again.
    Dolphin.Link.disconnect(link)
    Enum.each(ids(network), &Dolphin.Vehicles.forget/1)
  end

  # The first network's vehicles announce themselves within a heartbeat:
  # discovered, they own their system ids before any other network's is
  # heard. (Alone, there is nothing to wait for.) Not all heard within 30 s
  # of real time: the others would take some of their names, and the fleet
  # is not started.
  defp await_known(_network, []), do: :ok
  defp await_known(network, _others), do: await_known(network.sysids, network, 600)

  defp await_known(sysids, network, tries) do
    case Enum.reject(sysids, &match?({:ok, _}, Dolphin.Vehicles.Views.get(&1))) do
      [] ->
        :ok

      waiting when tries == 0 ->
        {:error, %Dolphin.Sim.Error{reason: :start_failed, message: "#{length(waiting)} of the first network's #{length(network.sysids)} vehicles were not heard within 30 s (the host too busy?)"},
         [network]}

      waiting ->
        Process.sleep(50)
        await_known(waiting, network, tries - 1)
    end
  end

  # Simulated vehicles announce themselves within a heartbeat, and have
  # booted (past MAV_STATE BOOT) 2 s of clock time later; a vehicle of a
  # later network is named once the ground station has told it from the
  # first network's vehicle of its system id (a second or so each).
  defp await_fleet(ids) do
    tries = 200 + div(Dolphin.Clock.to_real_ms(2_000), 50) + div(length(ids), 5)
    await_ready(ids, tries)
  end

  defp await_ready([], _tries), do: :ok
  defp await_ready(_ids, 0), do: :ok

  defp await_ready(ids, tries) do
    case Enum.reject(ids, &Dolphin.Vehicles.ready?/1) do
      [] ->
        :ok

      waiting ->
        Process.sleep(50)
        await_ready(waiting, tries - 1)
    end
  end
end
