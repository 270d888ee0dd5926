defmodule Dolphin.Link do
  @moduledoc """
  Connections to vehicles. `connect/2` starts a link for an endpoint string
  (see `Dolphin.Link.Endpoint`) under `Dolphin.Link.Supervisor`, which restarts
  it if it crashes; vehicles outlive their link's restarts.

      {:ok, _pid} = Dolphin.Link.connect("udpin:0.0.0.0:14550", tlog: "flight.tlog")

  UDP endpoints (`udpin`, `udpout`) are served by `Dolphin.Link.UDP`.
  """

  alias Dolphin.Link.Endpoint

  @doc "Starts a link. Options as for `Dolphin.Link.UDP.start_link/1` (but `:endpoint`)."
  @spec connect(String.t(), keyword()) :: {:ok, pid()} | {:error, String.t()}
  def connect(endpoint, opts \\ []) do
    with {:ok, %Endpoint{} = ep} <- Endpoint.parse(endpoint),
         :ok <- supported(ep) do
      case DynamicSupervisor.start_child(Dolphin.Link.Supervisor, {Dolphin.Link.UDP, [endpoint: ep] ++ opts}) do
        {:ok, pid} -> {:ok, pid}
        {:error, {:already_started, _}} -> {:error, "#{endpoint}: already connected"}
        {:error, {{:cannot_open, where, why}, _}} -> {:error, "#{where}: cannot open the socket: #{why}"}
        {:error, {:cannot_open, where, why}} -> {:error, "#{where}: cannot open the socket: #{why}"}
        {:error, other} -> {:error, "#{endpoint}: #{inspect(other)}"}
      end
    end
  end

  defp supported(%Endpoint{kind: :tcp} = ep), do: {:error, "#{Endpoint.to_string(ep)}: TCP links are not built yet"}
  defp supported(_ep), do: :ok
end
