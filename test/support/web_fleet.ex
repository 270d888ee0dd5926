defmodule Dolphin.Test.WebFleet do
  @moduledoc """
  Vehicles a live view (`Dolphin.Web`) discovers and sees, without a
  simulator: each id's discovery published, then, once the view has taken
  them (it follows a vehicle's views from its discovery on), its view.

      Dolphin.Test.WebFleet.show(web, ["1@webpages", "2@webpages"], fn id, i -> view end)
  """

  alias Dolphin.PubSub

  @doc "Publishes `ids` to the view `web`: discovered, then `view.(id, index)` each (index from 0)."
  def show(web, ids, view) do
    for id <- ids, do: PubSub.publish(:vehicles, {:vehicle_discovered, id})
    _ = :sys.get_state(web)
    for {id, i} <- Enum.with_index(ids), do: PubSub.publish({:vehicle, id}, {:view, view.(id, i)})
    :ok
  end
end
