defmodule Dolphin.Fleet.Allocation do
  @moduledoc """
  Which vehicle runs each platform task of a run: a pure function, called by
  the fleet (which knows the vehicles) when a run starts, on the leaves the
  engine describes (`t:leaf/0`).

  Constraints:

    * a task's requirements (type, payloads, id: see `Dolphin.Engine.Platform`)
      and its `allowed` vehicles (the engine's enclosing `on(t, set)`
      restrictions) are honoured;
    * tasks that may run at the same time get distinct vehicles: two tasks may
      run at the same time when, at the node of the task tree where their
      paths part, that node's children run `:together` (for the engine: `|||`
      and `all_of`); where they run `:apart` (a sequence, `one_of`, `until`
      and the like) they may share one.

  This is a real search (backtracking, most constrained task first, vehicles
  already given to a task that cannot run at the same time preferred — so a
  sequence keeps its vehicle), not a greedy first fit: it finds an allocation
  whenever one exists. When none does, the error names the task that cannot be
  served: the first task, in the script's order, that no allocation of it and
  the tasks before it can satisfy.

      iex> alias Dolphin.Fleet.Allocation
      iex> a = %{id: 1, name: "north", requirements: %{type: :uav}, allowed: nil, path: [{0, :together, 0}]}
      iex> b = %{id: 2, name: "south", requirements: %{}, allowed: nil, path: [{0, :together, 1}]}
      iex> vehicles = [%Dolphin.Vehicles.View{id: 1, type: :ugv}, %Dolphin.Vehicles.View{id: 2, type: :uav}]
      iex> Allocation.solve([a, b], vehicles)
      {:ok, %{1 => 2, 2 => 1}}
  """

  alias Dolphin.Fleet.{AllocationError, VehicleSet}
  alias Dolphin.Vehicles.View

  @typedoc """
  A platform task to place: `requirements` (`type`, `payloads`, `id`),
  `allowed` (the vehicle ids it may use, or nil for any), and `path`, the
  nodes from the root of its task tree down to it, each as `{node id, how
  that node's children run (:together | :apart), index of the child taken}`.
  """
  @type leaf :: %{
          id: integer(),
          name: String.t(),
          requirements: map(),
          allowed: [non_neg_integer()] | nil,
          path: [{integer(), :together | :apart, non_neg_integer()}]
        }

  @budget 200_000

  @doc "Whether two tasks may run at the same time (see the module doc)."
  @spec concurrent?(leaf(), leaf()) :: boolean()
  def concurrent?(%{path: a}, %{path: b}), do: diverge(a, b)

  defp diverge([{id, kind, i} | a], [{id, kind, i} | b]), do: diverge(a, b)
  defp diverge([{id, how, _} | _], [{id, how, _} | _]), do: how == :together
  defp diverge(_, _), do: false

  @doc "Whether a vehicle satisfies a task's requirements and restrictions."
  @spec matches?(leaf(), View.t()) :: boolean()
  def matches?(%{requirements: req, allowed: allowed}, %View{} = v) do
    (allowed == nil or Enum.any?(allowed, &View.named?(v, &1))) and type_ok?(req[:type], v.type) and type_ok?(req[:airframe], v.airframe) and
      Enum.all?(List.wrap(req[:payloads]), &(&1 in v.payloads)) and (req[:id] == nil or View.named?(v, req[:id]))
  end

  defp type_ok?(nil, _), do: true
  defp type_ok?(types, type), do: type in List.wrap(types)

  @doc """
  An allocation of `vehicles` (in order of preference) to `leaves`:
  `{:ok, %{task_id => vehicle_id}}` or `{:error, %AllocationError{}}`.
  """
  @spec solve([leaf()], [View.t()]) :: {:ok, %{integer() => non_neg_integer()}} | {:error, AllocationError.t()}
  def solve([], _vehicles), do: {:ok, %{}}

  def solve(leaves, vehicles) do
    candidates = Map.new(leaves, fn l -> {l.id, for(v <- vehicles, matches?(l, v), do: v.id)} end)

    case Enum.find(leaves, &(candidates[&1.id] == [])) do
      nil ->
        case search(leaves, candidates) do
          {:ok, assignment} -> {:ok, assignment}
          :none -> {:error, culprit(leaves, candidates, vehicles)}
          :budget -> {:error, error(hd(leaves), "the allocation search gave up after #{@budget} steps (too many tasks and vehicles)")}
        end

      leaf ->
        {:error, error(leaf, "no vehicle matches #{describe(leaf)}; the vehicles at hand: #{describe_vehicles(vehicles)}")}
    end
  end

  defp search(leaves, candidates) do
    ordered = Enum.sort_by(Enum.with_index(leaves), fn {l, i} -> {length(candidates[l.id]), i} end) |> Enum.map(&elem(&1, 0))

    case assign(ordered, candidates, %{}, %{}, @budget) do
      {:ok, assignment, _} -> {:ok, assignment}
      {:none, 0} -> :budget
      {:none, _} -> :none
    end
  end

  # by_vehicle: vehicle => leaves given to it. Returns {:ok, assignment, budget} | {:none, budget}.
  defp assign([], _cands, assignment, _by_vehicle, budget), do: {:ok, assignment, budget}
  defp assign(_leaves, _cands, _assignment, _by_vehicle, 0), do: {:none, 0}

  defp assign([leaf | rest], cands, assignment, by_vehicle, budget) do
    {shared, fresh} = Enum.split_with(cands[leaf.id], &Map.has_key?(by_vehicle, &1))

    Enum.reduce_while(shared ++ fresh, {:none, budget - 1}, fn v, {:none, budget} ->
      if budget > 0 and Enum.all?(Map.get(by_vehicle, v, []), &(not concurrent?(&1, leaf))) do
        case assign(rest, cands, Map.put(assignment, leaf.id, v), Map.update(by_vehicle, v, [leaf], &[leaf | &1]), budget) do
          {:ok, _, _} = ok -> {:halt, ok}
          {:none, budget} -> {:cont, {:none, budget}}
        end
      else
        {:cont, {:none, budget}}
      end
    end)
  end

  # The first leaf (in script order) whose prefix cannot be allocated.
  defp culprit(leaves, candidates, vehicles) do
    n = Enum.find(1..length(leaves), fn n -> not match?({:ok, _}, search(Enum.take(leaves, n), candidates)) end)
    {before, [leaf | _]} = Enum.split(leaves, n - 1)
    rivals = Enum.filter(before, fn l -> concurrent?(l, leaf) and Enum.any?(candidates[l.id], &(&1 in candidates[leaf.id])) end)

    error(
      leaf,
      "#{describe(leaf)} could use vehicle(s) #{VehicleSet.format(candidates[leaf.id])}, but they are needed at the same time by " <>
        Enum.map_join(rivals, ", ", &"#{inspect(&1.name)} (task #{&1.id})") <>
        "; the vehicles at hand: #{describe_vehicles(vehicles)}"
    )
  end

  defp error(leaf, why),
    do: %AllocationError{task_id: leaf.id, task_name: leaf.name, message: "cannot allocate a vehicle to #{inspect(leaf.name)} (task #{leaf.id}): #{why}"}

  defp describe(%{requirements: req, allowed: allowed}) do
    parts =
      [
        req[:type] && "type #{inspect(req[:type])}",
        req[:airframe] && "airframe #{inspect(req[:airframe])}",
        req[:payloads] not in [nil, []] && "payload #{inspect(req[:payloads])}",
        req[:id] && "id #{VehicleSet.format(req[:id])}",
        allowed && "one of #{VehicleSet.format(allowed)} (on)"
      ]
      |> Enum.filter(& &1)

    if parts == [], do: "(any vehicle)", else: Enum.join(parts, ", ")
  end

  defp describe_vehicles([]), do: "none (pick vehicles first; busy or lost ones do not count)"
  defp describe_vehicles(vs), do: Enum.map_join(vs, ", ", fn v -> "#{v.id} (#{View.describe_kind(v)}#{if v.payloads != [], do: " " <> inspect(v.payloads), else: ""})" end)
end
