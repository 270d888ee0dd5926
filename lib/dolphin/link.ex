defmodule Dolphin.Link do
  @moduledoc """
  Connections to vehicles. `connect/2` starts a link for an endpoint string
  (see `Dolphin.Link.Endpoint`) under `Dolphin.Link.Supervisor`, which restarts
  it if it crashes; vehicles outlive their link's restarts.

      {:ok, _pid} = Dolphin.Link.connect("udpin:0.0.0.0:14550", tlog: "flight.tlog")

  Every kind of endpoint (`udpin`, `udpout`, `tcp`) is served by `Dolphin.Link.Connection`.
  """

  alias Dolphin.Link.Endpoint

  @doc """
  Starts a link. Options as for `Dolphin.Link.Connection.start_link/1` (but
  `:endpoint`); `:forward` may be given as endpoint strings.
  """
  @spec connect(String.t(), keyword()) :: {:ok, pid()} | {:error, String.t()}
  def connect(endpoint, opts \\ []) do
    with {:ok, %Endpoint{} = ep} <- Endpoint.parse(endpoint),
         {:ok, forward} <- parse_all(Keyword.get(opts, :forward, [])) do
      opts = Keyword.put(opts, :forward, forward)

      case DynamicSupervisor.start_child(Dolphin.Link.Supervisor, {Dolphin.Link.Connection, [endpoint: ep] ++ opts}) do
        {:ok, pid} -> {:ok, pid}
        {:error, {:already_started, _}} -> {:error, "#{endpoint}: already connected"}
        {:error, {{:cannot_open, where, why}, _}} -> {:error, "#{where}: cannot open: #{why}"}
        {:error, {:cannot_open, where, why}} -> {:error, "#{where}: cannot open: #{why}"}
        {:error, other} -> {:error, "#{endpoint}: #{inspect(other)}"}
      end
    end
  end

  defp parse_all(endpoints) do
    Enum.reduce_while(endpoints, {:ok, []}, fn
      %Endpoint{} = ep, {:ok, acc} ->
        {:cont, {:ok, acc ++ [ep]}}

      string, {:ok, acc} ->
        case Endpoint.parse(string) do
          {:ok, ep} -> {:cont, {:ok, acc ++ [ep]}}
          error -> {:halt, error}
        end
    end)
  end
end
