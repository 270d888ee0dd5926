defmodule Dolphin.Fleet.Source do
  @moduledoc """
  Where the fleet's vehicles come from: the behaviour that keeps the engine
  independent of MAVLink.

  A source is `{module, arg}`; every callback gets `arg` first. Two exist:
  `Dolphin.Fleet.MAVLinkSource` (the real vehicles of `Dolphin.Vehicles`) and
  `Dolphin.Fleet.TestSource` (fake vehicles whose state tests set).

  Besides the callbacks, a source publishes on `Dolphin.PubSub`, with the shapes
  `Dolphin.Vehicles` uses:

    * topic `:vehicles`: `{:vehicle_discovered, id}`, `{:vehicle_lost, id}`,
      `{:vehicle_reconnected, id}`;
    * topic `{:vehicle, id}`: `{:state, id, changes}` (changes: an enumerable of
      `{field, value}` that `c:apply_changes/3` understands), and again
      `{:vehicle_lost, id}` and `{:vehicle_reconnected, id}`.

  The fleet and every running condition subscribe to these, so reactions follow
  events, not polling.
  """

  alias Dolphin.Fleet.Vehicle

  @type t :: {module(), term()}
  @type id :: non_neg_integer()

  @doc "The ids of the vehicles known now."
  @callback list(arg :: term()) :: [id()]

  @doc "A vehicle's identity and live state."
  @callback vehicle(arg :: term(), id()) :: {:ok, Vehicle.t()} | {:error, :unknown_vehicle}

  @doc "Folds the `changes` of a `{:state, id, changes}` event into a vehicle."
  @callback apply_changes(arg :: term(), Vehicle.t(), changes :: Enumerable.t()) :: Vehicle.t()

  @doc "Sets after how much clock time without news a vehicle is lost."
  @callback set_timeout(arg :: term(), id(), pos_integer()) :: :ok | {:error, :unknown_vehicle}

  @doc "Sends a raw message (for MAVLink, a message struct) to a vehicle."
  @callback send_message(arg :: term(), id(), term()) :: :ok | {:error, term()}

  @doc false
  def list({m, a}), do: m.list(a)
  @doc false
  def vehicle({m, a}, id), do: m.vehicle(a, id)
  @doc false
  def apply_changes({m, a}, v, changes), do: m.apply_changes(a, v, changes)
  @doc false
  def set_timeout({m, a}, id, ms), do: m.set_timeout(a, id, ms)
  @doc false
  def send_message({m, a}, id, msg), do: m.send_message(a, id, msg)
end
