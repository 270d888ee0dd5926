defmodule Dolphin.Fleet.Source do
  @moduledoc """
  Where the fleet's vehicles come from: the behaviour that keeps the engine
  independent of MAVLink.

  A source is `{module, arg}`; every callback gets `arg` first. Two exist:
  `Dolphin.Fleet.MAVLinkSource` (the real vehicles of `Dolphin.Vehicles`) and
  `Dolphin.Fleet.FakeSource` (fake vehicles whose state tests set).

  A source owns its vehicles' state: it answers `vehicle/2` and `views/1`
  from it, and announces every change with the shapes `Dolphin.Vehicles`
  uses (`Dolphin.Vehicles.Views.put/1` does all of it for real vehicles):

    * topic `{:vehicle, id}`: `{:view, %Dolphin.Vehicles.View{}}`, the
      whole view each time it changes (a loss or a reconnection too: the view
      is published before the `:vehicles` event);
    * topic `:vehicles`: `{:vehicle_discovered, id}`, `{:vehicle_lost, id}`,
      `{:vehicle_reconnected, id}`, `{:vehicle_forgotten, id}`, and
      `{:vehicle_changed, id}` when a view changes what picks match on but
      the position (type, payloads, connected?, or a first view);
    * the view's transitions (`Dolphin.Vehicles.View.transitions/2`) as
      `Dolphin.Events` events, unless told not to.

  The fleet keeps no copy: it reads views from the source when it picks,
  serves waiting picks, reserves or lists, and follows only `:vehicles`. The
  engine's condition watchers follow the views of the vehicles their
  conditions read, so reactions follow events, not polling.
  """

  alias Dolphin.Vehicles.View

  @type t :: {module(), term()}
  @type id :: non_neg_integer()

  @doc """
  Told when the fleet releases vehicles (a script's `release`, or its end):
  the source gives them back as it found them (a MAVLink vehicle its fence,
  `Dolphin.Vehicles.Fences.give_back/2`). Optional; must not block.
  """
  @callback released(arg :: term(), [id()]) :: :ok
  @optional_callbacks released: 2

  @doc "The ids of the vehicles known now."
  @callback list(arg :: term()) :: [id()]

  @doc "A vehicle's latest view."
  @callback vehicle(arg :: term(), id()) :: {:ok, View.t()} | {:error, :unknown_vehicle}

  @doc "Every vehicle's latest view, by ascending id."
  @callback views(arg :: term()) :: [View.t()]

  @doc "Sets after how much clock time without news a vehicle is lost."
  @callback set_timeout(arg :: term(), id(), pos_integer()) :: :ok | {:error, :unknown_vehicle}

  @doc "Sends a raw message (for MAVLink, a message struct) to a vehicle."
  @callback send_message(arg :: term(), id(), term()) :: :ok | {:error, term()}

  @doc """
  A vehicle's parameter `name`: read (`value` nil), or set to `value` and
  read back; typed (an integer for the integer types). Optional: a source
  without it has no parameters.
  """
  @callback param(arg :: term(), id(), String.t(), number() | nil) :: {:ok, number()} | {:error, Exception.t()}
  @optional_callbacks param: 4

  @doc false
  def list({m, a}), do: m.list(a)
  @doc false
  def vehicle({m, a}, id), do: m.vehicle(a, id)
  @doc false
  def views({m, a}), do: m.views(a)
  @doc false
  def set_timeout({m, a}, id, ms), do: m.set_timeout(a, id, ms)

  @doc false
  def released({m, a}, ids), do: if(function_exported?(m, :released, 2), do: m.released(a, ids), else: :ok)
  @doc false
  def send_message({m, a}, id, msg), do: m.send_message(a, id, msg)

  @doc false
  def param({m, a}, id, name, value) do
    Code.ensure_loaded(m)

    if function_exported?(m, :param, 4),
      do: m.param(a, id, name, value),
      else: {:error, %Dolphin.ParamError{param: name, vehicle: id, result: :unknown, asked: value && value * 1.0, detail: "its vehicles (#{inspect(m)}) have no parameters"}}
  end

  @doc "Subscribes the caller to a vehicle's views (`{:dolphin, {:vehicle, id}, {:view, view}}`), whatever the source."
  @spec subscribe(id()) :: :ok
  def subscribe(id), do: Dolphin.PubSub.subscribe({:vehicle, id})

  @doc "Undoes `subscribe/1`."
  @spec unsubscribe(id()) :: :ok
  def unsubscribe(id), do: Dolphin.PubSub.unsubscribe({:vehicle, id})
end
