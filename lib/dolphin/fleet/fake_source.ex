defmodule Dolphin.Fleet.FakeSource do
  @moduledoc """
  Fake vehicles for tests, benchmarks and dry runs (`mix dolphin.run --fake N`):
  a `Dolphin.Fleet.Source` whose vehicles' state the caller sets, publishing
  the same `Dolphin.PubSub` events as real vehicles do (a whole
  `Dolphin.Vehicles.View` on each change), so conditions react to them
  exactly as they react to telemetry.

      {:ok, _} = Dolphin.Fleet.FakeSource.start_link(name: :fakes)
      :ok = Dolphin.Fleet.FakeSource.add(:fakes, 1, type: :uav, payloads: [:camera])
      {:ok, fleet} = Dolphin.Fleet.start_link(name: :test_fleet, source: Dolphin.Fleet.FakeSource.source(:fakes))
      :ok = Dolphin.Fleet.FakeSource.set(:fakes, 1, battery: 0.25)   # {:view, %Dolphin.Vehicles.View{battery: 0.25}}
      :ok = Dolphin.Fleet.FakeSource.lose(:fakes, 1)                 # {:view, ...connected?: false}, {:vehicle_lost, 1}

  A vehicle's attributes are the fields of `Dolphin.Vehicles.View` (`type`
  defaults to `:uav`, `airframe` to the type's usual one,
  `Dolphin.Vehicles.View.stand_in_airframe/1` — a fake uav is a copter —, `battery` to 1.0, `position` to a point near Porto,
  `mission_progress` to `{0, 0}`, no mission; `nil` is a value not reported
  yet); a change is a keyword list of those fields. The state lives in a
  public ETS table named after the source, so `set/3` publishes from the
  caller with no process in between. Each change is announced as
  `Dolphin.Vehicles.Views.put/1` announces a real vehicle's: its view, its
  transitions as `Dolphin.Events` events (`vehicle_discovered`,
  `mode_changed`, `vehicle_lost`, ...; `Dolphin.Vehicles.View.transitions/2`),
  the same transitions as notices on `:vehicles` (`{:vehicle_discovered,
  id}`, `{:vehicle_lost, id}`, ...) and `{:vehicle_changed, id}` there when
  picks may see it anew; `events: false` keeps the telemetry quiet
  (stand-ins whose changes must not show in a real run's output, such as a
  pre-flight check's), not the notices. Vehicle ids are system ids: tests
  running at the same time should use different ones, as the pub/sub
  topics are shared.
  """

  use GenServer

  @behaviour Dolphin.Fleet.Source

  import Dolphin.Vehicles.Id, only: [is_id: 1]
  alias Dolphin.Vehicles.View

  # The table's row of the `events` option (vehicles' keys are integers).
  @events :"$events"
  @fields View.__struct__() |> Map.from_struct() |> Map.keys()

  @doc """
  Starts a source; options: `:name` (an atom, default `#{inspect(__MODULE__)}`),
  `:vehicles` (`[{id, attrs}]`), `:events` (emit the vehicles' transitions as
  telemetry, default true).
  """
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts \\ []) do
    name = Keyword.get(opts, :name, __MODULE__)
    events = Keyword.get(opts, :events, true)
    unless is_boolean(events), do: raise(ArgumentError, "events: must be true or false, got: #{inspect(events)}")
    GenServer.start_link(__MODULE__, {name, Keyword.get(opts, :vehicles, []), events}, name: name)
  end

  @doc false
  def child_spec(opts), do: %{id: Keyword.get(opts, :name, __MODULE__), start: {__MODULE__, :start_link, [opts]}}

  @doc "The `{module, arg}` pair to give `Dolphin.Fleet`."
  @spec source(atom()) :: Dolphin.Fleet.Source.t()
  def source(name \\ __MODULE__), do: {__MODULE__, name}

  @doc "Adds a vehicle (or replaces one) and publishes its view: a new one is discovered (`{:vehicle_discovered, id}` on `:vehicles`)."
  @spec add(atom(), Dolphin.Vehicles.Id.t(), keyword()) :: :ok
  def add(name, id, attrs \\ []) when is_id(id) do
    attrs = check!(attrs)
    # An airframe not given is the class's usual one (a fake uav is a copter).
    attrs = Keyword.put_new_lazy(attrs, :airframe, fn -> View.stand_in_airframe(Keyword.get(attrs, :type, :uav)) end)
    vehicle = struct!(%View{id: id, type: :uav, battery: 1.0, position: Dolphin.Geo.Location.new(41.1780, -8.5980, 100), mission_progress: {0, 0}}, attrs)
    put(name, %{vehicle | id: id, payloads: Enum.sort(vehicle.payloads)})
  end

  @doc "Changes a vehicle's state and publishes its new view."
  @spec set(atom(), non_neg_integer(), keyword()) :: :ok
  def set(name, id, changes), do: put(name, change(fetch!(name, id), check!(changes)))

  @doc "Makes a vehicle silent: it is lost (its view, then `{:vehicle_lost, id}` on `:vehicles`)."
  @spec lose(atom(), non_neg_integer()) :: :ok
  def lose(name, id), do: put(name, %{fetch!(name, id) | connected?: false})

  @doc "Brings a lost vehicle back (its view, then `{:vehicle_reconnected, id}` on `:vehicles`)."
  @spec reconnect(atom(), non_neg_integer()) :: :ok
  def reconnect(name, id), do: put(name, %{fetch!(name, id) | connected?: true})

  # The table holds each vehicle's one copy of its state; every change is
  # announced whole, with its transitions, as a real vehicle's is.
  defp put(name, %View{id: id} = v) do
    old =
      case :ets.lookup(name, id) do
        [{^id, old}] -> old
        [] -> nil
      end

    :ets.insert(name, {id, v})
    Dolphin.Vehicles.Views.announce(old, v, :ets.lookup_element(name, @events, 2))
  end

  defp change(%View{} = v, changes) do
    Enum.reduce(changes, v, fn
      {:payloads, p}, v -> %{v | payloads: Enum.sort(p)}
      {field, value}, v -> Map.put(v, field, value)
    end)
  end

  @doc "Forgets a vehicle, as `Dolphin.Vehicles.forget/1` does a real one: no \"lost\" event, but `{:vehicle_forgotten, id}`."
  @spec remove(atom(), non_neg_integer()) :: :ok
  def remove(name, id) do
    :ets.delete(name, id)
    Dolphin.Vehicles.Views.forgotten(id)
  end

  @doc "The messages sent to a vehicle with `send_message`, oldest first."
  @spec messages(atom(), non_neg_integer()) :: [term()]
  def messages(name, id), do: for({{:sent, ^id, n}, m} <- :ets.tab2list(name), do: {n, m}) |> Enum.sort() |> Enum.map(&elem(&1, 1))

  @doc "The connection timeout last set for a vehicle, or nil."
  @spec timeout(atom(), non_neg_integer()) :: pos_integer() | nil
  def timeout(name, id) do
    case :ets.lookup(name, {:timeout, id}) do
      [{_, ms}] -> ms
      [] -> nil
    end
  end

  defp fetch!(name, id) do
    case :ets.lookup(name, id) do
      [{^id, v}] -> v
      [] -> raise ArgumentError, "no fake vehicle #{inspect(id)} in #{inspect(name)}"
    end
  end

  defp check!(attrs) do
    Enum.each(attrs, fn
      {field, _} when field in @fields and field != :id -> :ok
      other -> raise ArgumentError, "not a vehicle field: #{inspect(other)} (fields: #{inspect(@fields -- [:id])})"
    end)

    attrs
  end

  # Source callbacks

  @impl Dolphin.Fleet.Source
  def list(name), do: for({id, %View{}} when is_id(id) <- :ets.tab2list(name), do: id) |> Enum.sort()

  @impl Dolphin.Fleet.Source
  def views(name), do: name |> :ets.select([{{:"$1", :"$2"}, [{:orelse, {:is_integer, :"$1"}, {:is_binary, :"$1"}}], [:"$2"]}]) |> Enum.sort_by(& &1.id)

  @impl Dolphin.Fleet.Source
  def vehicle(name, id) do
    case :ets.lookup(name, id) do
      [{^id, v}] -> {:ok, v}
      [] -> {:error, :unknown_vehicle}
    end
  end

  @impl Dolphin.Fleet.Source
  def set_timeout(name, id, ms) do
    case :ets.lookup(name, id) do
      [_] -> ok(:ets.insert(name, {{:timeout, id}, ms}))
      [] -> {:error, :unknown_vehicle}
    end
  end

  @impl Dolphin.Fleet.Source
  def send_message(name, id, message) do
    case :ets.lookup(name, id) do
      [_] -> ok(:ets.insert(name, {{:sent, id, System.unique_integer([:monotonic])}, message}))
      [] -> {:error, :unknown_vehicle}
    end
  end

  # A fake vehicle's parameters are what was set: a read of one never set is unknown.
  @impl Dolphin.Fleet.Source
  def param(name, id, param, value) do
    case {:ets.lookup(name, id), value, :ets.lookup(name, {:param, id, param})} do
      {[], _, _} -> {:error, %Dolphin.ParamError{param: param, vehicle: id, result: :vehicle_gone, attempts: 0, detail: "no such vehicle"}}
      {[_], nil, [{_, kept}]} -> {:ok, kept}
      {[_], nil, []} -> {:error, %Dolphin.ParamError{param: param, vehicle: id, result: :unknown, attempts: 0, detail: "a fake vehicle has only the parameters set on it"}}
      {[_], value, _} -> ok(:ets.insert(name, {{:param, id, param}, value})) && {:ok, value}
    end
  end

  defp ok(true), do: :ok

  @impl GenServer
  def init({name, vehicles, events}) do
    :ets.new(name, [:named_table, :public, :set, read_concurrency: true])
    :ets.insert(name, {@events, events})
    Enum.each(vehicles, fn {id, attrs} -> add(name, id, attrs) end)
    {:ok, name}
  end
end
