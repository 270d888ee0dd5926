defmodule Dolphin.Mission.MismatchError do
  @moduledoc """
  A mission read back from a vehicle that differs in meaning from the one
  uploaded (`Dolphin.Mission.compare_download/2`): the first difference,
  `what` differs (`:count`, `:command`, `:frame`, `:position`, `:height`;
  for a fence item `:param1`, its corner count or radius),
  in which `item` (its seq; nil for `:count`), as it is `on_vehicle` and as it
  was `uploaded`.

      iex> Exception.message(%Dolphin.Mission.MismatchError{what: :command, item: 2, on_vehicle: 177, uploaded: 178})
      "item 2 is command 177 on the vehicle, 178 was uploaded"
  """

  defexception [:what, :item, :on_vehicle, :uploaded]

  @type t :: %__MODULE__{
          what: :count | :command | :frame | :position | :height | :param1,
          item: non_neg_integer() | nil,
          on_vehicle: term(),
          uploaded: term()
        }

  @impl true
  def message(%__MODULE__{what: what, item: item, on_vehicle: down, uploaded: up}) do
    case what do
      :count -> "the vehicle has #{down} items, #{up} were uploaded"
      :command -> "item #{item} is command #{down} on the vehicle, #{up} was uploaded"
      :frame -> "item #{item} has frame #{down} on the vehicle, #{up} was uploaded"
      :position -> "item #{item} is at #{inspect(down)} on the vehicle, #{inspect(up)} was uploaded"
      :height -> "item #{item} is at height #{inspect(down)} on the vehicle, #{up} was uploaded"
      :param1 -> "item #{item} has param1 #{inspect(down)} on the vehicle, #{up} was uploaded"
    end
  end
end
