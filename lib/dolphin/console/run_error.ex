defmodule Dolphin.Console.RunError do
  @moduledoc """
  A run of the console (`Dolphin.Console.Runs.start_task/2`,
  `Dolphin.Console.Runs.start_script/2`) that could not start. `reason`:

    * `:no_free_vehicle` — no known vehicle is free;
    * `:not_free` — the `vehicles` asked for (`on:`) are not all free;
      `detail` lists those taken;
    * `:bad_vehicles` — `on:` names no vehicles (`detail` says why);
    * `:pick_failed` — the fleet did not give the `vehicles` (`cause`: its
      `Dolphin.Fleet.PickError`);
    * `:no_fit` — no vehicle fits the task (`cause`: the allocation's error);
    * `:worker_exit` — the run's worker ended before it started (`detail`: how).

      iex> Exception.message(%Dolphin.Console.RunError{reason: :not_free, vehicles: [2, 3], detail: [3]})
      "vehicle 3 is not free (lost, picked or busy: see vehicles())"
  """

  defexception [:reason, :vehicles, :detail, :cause]

  @type reason :: :no_free_vehicle | :not_free | :bad_vehicles | :pick_failed | :no_fit | :worker_exit
  @type t :: %__MODULE__{reason: reason(), vehicles: [integer()] | nil, detail: term(), cause: Exception.t() | nil}

  @impl true
  def message(%__MODULE__{} = e) do
    case e.reason do
      :no_free_vehicle ->
        "no vehicle is free (every known vehicle is lost, picked or busy: see vehicles())"

      :not_free ->
        {s, verb} = if length(e.detail) > 1, do: {"s", "are"}, else: {"", "is"}
        "vehicle#{s} #{Enum.join(e.detail, ", ")} #{verb} not free (lost, picked or busy: see vehicles())"

      :bad_vehicles ->
        "on: " <> e.detail

      :pick_failed ->
        "cannot pick [#{Enum.join(e.vehicles, ", ")}]: #{Exception.message(e.cause)}"

      :no_fit ->
        "no vehicle fits: " <> Exception.message(e.cause)

      :worker_exit ->
        "could not start: its console worker #{e.detail}"
    end
  end
end
