defmodule Dolphin.CLI.Vehicles do
  @moduledoc false
  # The vehicles a run of `mix dolphin.run` asks for: its links (--connect,
  # else the configured ones, else the default endpoint), simulated vehicles
  # (--sim), SITL instances (--sitl) or fake ones (--fake). Each thing started
  # hands its undoing to `defer` at once, so that a run that fails half way
  # still stops what it started.

  alias Dolphin.Fleet.FakeSource

  @doc false
  # `opts`: the run's options (those of Mix.Tasks.Dolphin.Run, :tlog resolved,
  # :sitl_extra); `out`: where to say what was started.
  @spec start(keyword(), IO.device(), (fun() -> any())) :: :ok | {:error, Dolphin.CommandLineError.t()}
  def start(opts, out, defer) do
    link_opts = Enum.reject([tlog: opts[:tlog], forward: Keyword.get_values(opts, :forward)], fn {_, v} -> v in [nil, []] end)

    with :ok <- fleet_payloads(opts[:fleet], out, defer),
         :ok <- connect_all(Keyword.get_values(opts, :connect), link_opts, defer) do
      cond do
        n = opts[:sim] -> start_sim(n, opts, link_opts, out, defer)
        n = opts[:sitl] -> start_sitl(n, opts, link_opts, out, defer)
        n = opts[:fake] -> start_fake(n, out, defer)
        # Joined stations bring the vehicles: no default link then.
        opts[:connect] != nil or opts[:join] != nil or Application.get_env(:dolphin, :links, []) != [] -> :ok
        true -> listen_default(link_opts, out, defer)
      end
    end
  end

  @doc false
  # The fleet file's vehicles (--fleet FILE), or an error naming its problems.
  @spec fleet_file(Path.t()) :: {:ok, [Dolphin.Check.FleetFile.vehicle()]} | {:error, Dolphin.CommandLineError.t()}
  def fleet_file(path) do
    with {:error, e} <- Dolphin.Check.FleetFile.read(path, position: :optional), do: {:error, Dolphin.CommandLineError.failed("--fleet #{path}", e)}
  end

  # What the fleet file says each vehicle carries, given to it (by system id)
  # before it is heard, and taken back when the run ends.
  defp fleet_payloads(nil, _out, _defer), do: :ok

  defp fleet_payloads(path, out, defer) do
    with {:ok, vehicles} <- fleet_file(path) do
      given =
        for %{id: id, payloads: payloads} <- vehicles, payloads != [] do
          Dolphin.Vehicles.put_payloads(id, payloads ++ Dolphin.Vehicles.given_payloads(id))
          defer.(fn -> Dolphin.Vehicles.put_payloads(id, Dolphin.Vehicles.given_payloads(id) -- payloads) end)
          "#{id} #{inspect(payloads)}"
        end

      IO.puts(out, "payloads from #{path}: #{if given == [], do: "none", else: Enum.join(given, ", ")}")
    end
  end

  # Told nothing: listen where vehicles and simulators send by default.
  defp listen_default(link_opts, out, defer) do
    endpoint = Dolphin.Link.default_endpoint()

    with :ok <- connect_all([endpoint], link_opts, defer) do
      IO.puts(out, "listening on #{endpoint} (no --connect, --sim or --fake given)")
    end
  end

  @doc false
  # Opens a link to each endpoint, its undoing handed to `defer`; the first
  # that cannot be opened is the error (mix dolphin.station opens its links so too).
  @spec connect_all([String.t()], keyword(), (fun() -> any())) :: :ok | {:error, Dolphin.CommandLineError.t()}
  def connect_all(endpoints, link_opts, defer) do
    Enum.reduce_while(endpoints, :ok, fn ep, :ok ->
      case Dolphin.Link.connect(ep, link_opts) do
        {:ok, pid} ->
          defer.(fn -> Dolphin.Link.disconnect(pid) end)
          {:cont, :ok}

        {:error, why} ->
          {:halt, {:error, Dolphin.CommandLineError.failed("--connect #{ep}", why)}}
      end
    end)
  end

  defp start_sim(n, opts, link_opts, out, defer) do
    with {:ok, world} <- world(opts[:world]),
         {:ok, carried} <- fleet_sensors(opts[:fleet]) do
      case Dolphin.Sim.Local.start(n, [seed: Keyword.get(opts, :seed, 1), home: opts[:home], world: world, sensors: carried] ++ link_opts) do
        {:ok, sim} ->
          defer.(fn -> Dolphin.Sim.Local.stop(sim) end)
          IO.puts(out, "#{sim_words(n)} #{Dolphin.Sim.Local.describe(sim)}")
          :ok

        {:error, why} ->
          {:error, Dolphin.CommandLineError.failed(nil, why)}
      end
    end
  end

  @doc false
  # The sensors the fleet file (--fleet) gives simulated vehicles, by system id.
  @spec fleet_sensors(Path.t() | nil) :: {:ok, %{byte() => [atom()]}} | {:error, Dolphin.CommandLineError.t()}
  def fleet_sensors(nil), do: {:ok, %{}}

  def fleet_sensors(path) do
    with {:ok, vehicles} <- fleet_file(path), do: {:ok, for(%{id: id, sensors: [_ | _] = s} <- vehicles, into: %{}, do: {id, s})}
  end

  @doc false
  # The world file of --world (`Dolphin.Sim.World`), or what is wrong in it (its line and key).
  @spec world(Path.t() | nil) :: {:ok, Dolphin.Sim.World.t() | nil} | {:error, Dolphin.CommandLineError.t()}
  def world(nil), do: {:ok, nil}

  def world(path) do
    with {:error, why} <- Dolphin.Sim.World.read(path), do: {:error, Dolphin.CommandLineError.failed("--world", why)}
  end

  defp start_sitl(n, opts, link_opts, out, defer) do
    sitl_opts = [bin: opts[:sitl_bin], defaults: Keyword.get_values(opts, :sitl_defaults), home: opts[:home]] ++ link_opts ++ Keyword.get(opts, :sitl_extra, [])

    with {:ok, fleet, lines} <- sitl_fleet(n, sitl_opts, opts, defer) do
      defer.(fn -> Dolphin.SITL.stop(fleet) end)
      Enum.each(lines, &IO.puts(out, &1))
      IO.puts(out, "#{sitl_words(n)}, vehicles #{Enum.join(fleet.sysids, ", ")}, on 127.0.0.1:#{fleet.port} at #{Dolphin.Clock.speedup()}x")
    end
  end

  @doc false
  # `--sitl N` or `--sitl copter:2+smoke,...`: the SITL fleet, with a sensor
  # sidecar as the companion computer of the vehicles that carry sensors
  # (sensing --world); what to say of the sidecar. `defer` gets its undoing.
  @spec sitl_fleet(pos_integer() | list(), keyword(), keyword(), (fun() -> any())) :: {:ok, Dolphin.SITL.t(), [String.t()]} | {:error, Dolphin.CommandLineError.t()}
  def sitl_fleet(n, sitl_opts, opts, defer) do
    groups = Dolphin.Sim.Local.groups(n)
    fleet = if is_integer(n), do: n, else: Enum.map(groups, fn {airframe, count, _} -> {airframe, count} end)

    # A wrong world file is said before anything starts, sensors or not.
    with {:ok, _world} <- world(opts[:world]),
         {:ok, companion, lines} <- sidecar(groups, opts, defer) do
      case Dolphin.SITL.start(fleet, Enum.reject(sitl_opts ++ [companion_port: companion], fn {_, v} -> v in [nil, []] end)) do
        {:ok, fleet} -> {:ok, fleet, lines}
        {:error, why} -> {:error, Dolphin.CommandLineError.failed(nil, why)}
      end
    end
  end

  # The companion computers of the SITL vehicles that carry sensors: a
  # sidecar on their second telemetry port. Its port, or nil when no
  # vehicle carries one.
  defp sidecar(groups, opts, defer) do
    with {:ok, carried} <- fleet_sensors(opts[:fleet]) do
      groups
      |> Enum.flat_map(fn {_airframe, count, sensors} -> List.duplicate(sensors, count) end)
      |> Enum.with_index(1)
      |> Map.new(fn {sensors, sysid} -> {sysid, Enum.uniq(sensors ++ Map.get(carried, sysid, []))} end)
      |> start_sidecar(opts, defer)
    end
  end

  defp start_sidecar(by_sysid, opts, defer) do
    if Enum.all?(Map.values(by_sysid), &(&1 == [])) do
      {:ok, nil, []}
    else
      with {:ok, world} <- world(opts[:world]) do
        {:ok, pid} = Dolphin.Sim.Sidecar.start_link(listen: 0, sensors: by_sysid, world: world, seed: Keyword.get(opts, :seed, 1))
        Process.unlink(pid)
        defer.(fn -> Dolphin.Sim.Sidecar.stop(pid) end)
        port = Dolphin.Sim.Sidecar.port(pid)
        {:ok, port, ["sensor sidecar on 127.0.0.1:#{port} (the SITL vehicles' --serial1)"]}
      end
    end
  end

  @doc false
  # What --sim started, in words: "2 simulated vehicle(s)", "4 simulated vehicle(s) (1 boat, 3 sub)".
  @spec sim_words(pos_integer() | list()) :: String.t()
  def sim_words(n) when is_integer(n), do: "#{n} simulated vehicle(s)"

  def sim_words(fleet) do
    groups = Dolphin.Sim.Local.groups(fleet)
    total = groups |> Enum.map(&elem(&1, 1)) |> Enum.sum()
    "#{total} simulated vehicle(s) (#{Enum.map_join(groups, ", ", fn {a, n, sensors} -> "#{n} #{a}#{Enum.map(sensors, &"+#{&1}")}" end)})"
  end

  @doc false
  # What --sitl started, in words: "2 ArduCopter SITL instance(s)", "3 SITL instance(s): 1 plane, 2 boat".
  @spec sitl_words(pos_integer() | keyword()) :: String.t()
  def sitl_words(n) when is_integer(n), do: "#{n} ArduCopter SITL instance(s)"

  def sitl_words(fleet) do
    groups = Dolphin.Sim.Local.groups(fleet)
    total = groups |> Enum.map(&elem(&1, 1)) |> Enum.sum()
    "#{total} SITL instance(s) (#{Enum.map_join(groups, ", ", fn {a, n, sensors} -> "#{n} #{a}#{Enum.map(sensors, &"+#{&1}")}" end)})"
  end

  defp start_fake(n, out, defer) do
    name = :"dolphin_run_fakes_#{System.unique_integer([:positive])}"
    {:ok, source} = FakeSource.start_link(name: name)
    Process.unlink(source)
    defer.(fn -> GenServer.stop(source) end)
    previous = Dolphin.Fleet.source()
    :ok = Dolphin.Fleet.set_source(FakeSource.source(name))
    defer.(fn -> Dolphin.Fleet.set_source(previous) end)
    for id <- 1..n, do: FakeSource.add(name, id, type: :uav, airframe: :copter)
    IO.puts(out, "#{n} fake vehicle(s) [1..#{n}] of the fake platform (no MAVLink: missions cannot fly on them)")
    :ok
  end

  @doc false
  # Where the run's telemetry log goes (nil: none). Every run that talks
  # MAVLink keeps one unless told not to: logs/<date>_<time>-<script>.tlog,
  # readable by pymavlink, MAVExplorer and `mix mavlink.decode --tlog`.
  @spec tlog_path(keyword(), Path.t()) :: Path.t() | nil
  def tlog_path(opts, file) do
    cond do
      opts[:no_tlog] || opts[:fake] ->
        nil

      path = opts[:tlog] ->
        path

      true ->
        {{y, mo, d}, {h, mi, sec}} = :calendar.local_time()
        stamp = :io_lib.format("~4..0B-~2..0B-~2..0B_~2..0B-~2..0B-~2..0B", [y, mo, d, h, mi, sec]) |> IO.iodata_to_binary()
        File.mkdir_p!("logs")
        base = Path.join("logs", "#{stamp}-#{Path.basename(file, ".exs")}")
        # Two runs of one script in the same second get two logs.
        Enum.find(Stream.map(Stream.iterate(1, &(&1 + 1)), &"#{base}#{if &1 > 1, do: "-#{&1}"}.tlog"), &(not File.exists?(&1)))
    end
  end
end
