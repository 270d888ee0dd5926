defmodule Dolphin.CLI.OneVehicle do
  @moduledoc false
  # The one vehicle a command-line transfer talks to (`mix dolphin.plan
  # upload/download`, `mix dolphin.param`): a link opened to --connect, the
  # vehicle --vehicle names (or the only one heard), once it has booted;
  # the link closed and its vehicles forgotten afterwards.

  @doc false
  # Runs `fun` with the vehicle's id; `{:error, {:usage, text}}` when no
  # --connect was given, `{:error, text}` when no vehicle could be found.
  @spec with_vehicle(String.t(), keyword(), (Dolphin.Vehicles.Id.t() -> result)) :: result | {:error, term()} when result: term()
  def with_vehicle(task, opts, fun) do
    name = "#{task}-#{System.unique_integer([:positive])}"

    with {:ok, endpoint} <- (opts[:connect] && {:ok, opts[:connect]}) || {:error, {:usage, "--connect ENDPOINT is needed"}},
         {:ok, link} <- connect(endpoint, name) do
      try do
        with {:ok, id} <- find_vehicle(endpoint, opts[:vehicle], round(Keyword.get(opts, :timeout, 10) * 1_000)), do: fun.(id)
      after
        heard = Dolphin.Vehicles.list()
        Dolphin.Link.disconnect(link)
        Enum.each(heard, &Dolphin.Vehicles.forget/1)
      end
    end
  end

  defp connect(endpoint, name) do
    case Dolphin.Link.connect(endpoint, name: name) do
      {:ok, link} -> {:ok, link}
      # The endpoint was read with the options: what is left is a link that would not open.
      {:error, e} -> {:error, "--connect #{endpoint}: #{Exception.message(e)}"}
    end
  end

  @poll_ms 50
  # Once one vehicle is heard, others on the link get this long to show up.
  @others_ms 1_500

  # The vehicle asked for, or the only one heard, once it has booted
  # (ArduCopter refuses uploads while it boots).
  defp find_vehicle(endpoint, wanted, timeout_ms) do
    deadline = System.monotonic_time(:millisecond) + timeout_ms
    await_vehicle(endpoint, wanted, deadline, nil)
  end

  defp await_vehicle(endpoint, wanted, deadline, first_heard) do
    now = System.monotonic_time(:millisecond)
    heard = Dolphin.Vehicles.list()
    first_heard = first_heard || (heard != [] && now) || nil
    # The first vehicle of a system id answers to its qualified name too.
    wanted = wanted && Dolphin.Vehicles.resolve(wanted)

    cond do
      wanted != nil and wanted in heard and Dolphin.Vehicles.ready?(wanted) ->
        {:ok, wanted}

      wanted == nil and length(heard) > 1 ->
        {:error, "vehicles #{Enum.join(Enum.sort(heard), ", ")} are on #{endpoint}: say which with --vehicle ID"}

      wanted == nil and heard != [] and now - first_heard >= @others_ms and Dolphin.Vehicles.ready?(hd(heard)) ->
        {:ok, hd(heard)}

      now >= deadline ->
        cond do
          wanted != nil and wanted in heard -> {:error, "vehicle #{wanted} on #{endpoint} did not finish booting in time (--timeout)"}
          wanted != nil -> {:error, "no vehicle #{wanted} heard on #{endpoint} (heard: #{if heard == [], do: "none", else: Enum.join(Enum.sort(heard), ", ")})"}
          heard != [] -> {:error, "vehicle #{hd(heard)} on #{endpoint} did not finish booting in time (--timeout)"}
          true -> {:error, "no vehicle heard on #{endpoint} within #{div(deadline - now + 999, 1000) |> max(0)} s (--timeout)"}
        end

      true ->
        Process.sleep(@poll_ms)
        await_vehicle(endpoint, wanted, deadline, first_heard)
    end
  end
end
