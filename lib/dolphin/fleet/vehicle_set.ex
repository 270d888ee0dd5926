defmodule Dolphin.Fleet.VehicleSet do
  @moduledoc """
  A set of vehicles, named by their ids (`Dolphin.Vehicles.Id`: a system id,
  or a qualified name `"SYSID@NETWORK"` for another vehicle with that system
  id): what `pick` returns and `release`, `on` and `execute` take. System
  ids come first, ascending, then qualified names.

      iex> a = Dolphin.Fleet.VehicleSet.new([3, 1])
      #Vehicles<[1, 3]>
      iex> Dolphin.Fleet.VehicleSet.union(a, Dolphin.Fleet.VehicleSet.new([2]))
      #Vehicles<[1, 2, 3]>
      iex> Enum.map(a, &Dolphin.Fleet.VehicleSet.ids/1)
      [[1], [3]]

  It is `Enumerable`, one one-vehicle set at a time, so `for v <- set` and
  `Enum.filter/2` work as Dolphin's `ns | {pred}` does.
  """

  import Dolphin.Vehicles.Id, only: [is_id: 1]

  defstruct ids: []

  @type id :: Dolphin.Vehicles.Id.t()
  @type t :: %__MODULE__{ids: [id()]}

  @doc "A set of the given vehicle ids (or of the vehicles of other sets)."
  @spec new([id() | t()] | id() | t()) :: t()
  def new(%__MODULE__{} = set), do: set
  def new(id) when is_id(id), do: new([id])

  def new(ids) when is_list(ids) do
    ids =
      Enum.flat_map(ids, fn
        %__MODULE__{ids: ids} -> ids
        id -> if Dolphin.Vehicles.Id.valid?(id), do: [id], else: raise(ArgumentError, "a vehicle is a system id (an integer 0..255) or a name \"SYSID@NETWORK\", got: #{inspect(id)}")
      end)

    %__MODULE__{ids: ids |> Enum.uniq() |> Enum.sort()}
  end

  def new(other), do: raise(ArgumentError, "expected vehicle ids or a vehicle set, got: #{inspect(other)}")

  @doc "The vehicle ids: system ids ascending, then qualified names."
  @spec ids(t()) :: [id()]
  def ids(%__MODULE__{ids: ids}), do: ids

  @doc "Vehicles in either set."
  @spec union(t(), t()) :: t()
  def union(a, b), do: new([new(a), new(b)])

  @doc "Vehicles of `a` that are not in `b`."
  @spec difference(t(), t()) :: t()
  def difference(a, b), do: %__MODULE__{ids: new(a).ids -- new(b).ids}

  @doc "Vehicles in both sets."
  @spec intersection(t(), t()) :: t()
  def intersection(a, b), do: %__MODULE__{ids: Enum.filter(new(a).ids, &(&1 in new(b).ids))}

  @doc "The vehicles `fun` keeps; it is given one-vehicle sets."
  @spec filter(t(), (t() -> as_boolean(term()))) :: t()
  def filter(set, fun) when is_function(fun, 1), do: %__MODULE__{ids: Enum.filter(new(set).ids, &fun.(%__MODULE__{ids: [&1]}))}

  @doc "The number of vehicles."
  @spec size(t()) :: non_neg_integer()
  def size(%__MODULE__{ids: ids}), do: length(ids)

  @doc """
  Vehicle ids as text for people: one id as its number (or its qualified
  name), a list of ids or a set as a bracketed list of them. Every message, event line and table that
  names vehicles prints them through this.

      iex> Dolphin.Fleet.VehicleSet.format([9, 99])
      "[9, 99]"
      iex> Dolphin.Fleet.VehicleSet.format(Dolphin.Fleet.VehicleSet.new(99))
      "[99]"
      iex> Dolphin.Fleet.VehicleSet.format(99)
      "99"
      iex> Dolphin.Fleet.VehicleSet.format([1, "1@radio2"])
      "[1, 1@radio2]"
  """
  # `inspect/1` would print a list whose ids all happen to be printable
  # character codes as a charlist ([99] as 'c'), so the list is spelled out.
  @spec format(t() | [id()] | id()) :: String.t()
  def format(%__MODULE__{ids: ids}), do: format(ids)
  def format(id) when is_integer(id), do: Integer.to_string(id)
  def format(id) when is_binary(id), do: id
  def format(ids) when is_list(ids), do: "[" <> Enum.map_join(ids, ", ", &format/1) <> "]"
  def format(other), do: inspect(other, charlists: :as_lists)

  @doc "The one vehicle of a one-vehicle set (or a bare vehicle id); raises `ArgumentError` otherwise."
  @spec one!(t() | id(), atom()) :: id()
  def one!(set, function \\ :vehicle)
  def one!(%__MODULE__{ids: [id]}, _function), do: id

  def one!(id, function) do
    if Dolphin.Vehicles.Id.valid?(id),
      do: id,
      else: raise(ArgumentError, "#{function} needs a one-vehicle set, got: #{inspect(id, charlists: :as_lists)}")
  end

  defimpl Enumerable do
    import Dolphin.Vehicles.Id, only: [is_id: 1]

    def count(%{ids: ids}), do: {:ok, length(ids)}
    def member?(%{ids: ids}, %Dolphin.Fleet.VehicleSet{ids: [id]}), do: {:ok, id in ids}
    def member?(%{ids: ids}, id) when is_id(id), do: {:ok, id in ids}
    def member?(_set, _other), do: {:ok, false}
    def slice(_set), do: {:error, __MODULE__}

    def reduce(%{ids: ids}, acc, fun),
      do: Enumerable.List.reduce(Enum.map(ids, &%Dolphin.Fleet.VehicleSet{ids: [&1]}), acc, fun)
  end

  defimpl Inspect do
    def inspect(set, _opts), do: "#Vehicles<#{Dolphin.Fleet.VehicleSet.format(set)}>"
  end
end
