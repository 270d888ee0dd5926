defmodule Dolphin.Link do
  @moduledoc """
  Connections to vehicles. `connect/2` starts a link for an endpoint string
  (see `Dolphin.Link.Endpoint`) under `Dolphin.Link.Supervisor`, which restarts
  it if it crashes; vehicles outlive their link's restarts. `disconnect/1`
  stops it, its socket closed when it returns.

      {:ok, link} = Dolphin.Link.connect("udpin:0.0.0.0:14550", tlog: "flight.tlog")
      :ok = Dolphin.Link.disconnect(link)

  Every kind of endpoint (`udpin`, `udpout`, `tcp`) is served by `Dolphin.Link.Connection`.

  Links can also come from the configuration, connected when the application
  starts (several at once), with their options:

      config :dolphin,
        links: ["udpin:0.0.0.0:14550", {"tcp:127.0.0.1:5760", tlog: "sitl.tlog"}],
        forward: ["udpout:127.0.0.1:14551"],   # given to every configured link
        gcs_sysid: 255                          # our system id on every link

  Nothing is connected unless configured or asked for; `default_endpoint/0` is
  where a ground station listens when told nothing else (QGroundControl's and
  MAVProxy's port), for tools such as `mix dolphin.run` to use.
  """

  alias Dolphin.Link.{Endpoint, EndpointError}

  @doc "Where a ground station listens when told nothing else: `udpin:0.0.0.0:14550`."
  @spec default_endpoint() :: String.t()
  def default_endpoint, do: "udpin:0.0.0.0:14550"

  @doc false
  # The application's child that connects the configured links: :ignore once
  # they are up, or the reason the application cannot start.
  def start_configured do
    connect_configured()
    :ignore
  rescue
    e in ArgumentError -> {:error, Exception.message(e)}
  end

  @doc false
  # Connects the links of `config :dolphin, links:`.
  @spec connect_configured() :: :ok
  def connect_configured do
    forward = Application.get_env(:dolphin, :forward, [])

    for link <- Application.get_env(:dolphin, :links, []) do
      {endpoint, opts} = if is_tuple(link), do: link, else: {link, []}

      case connect(endpoint, Keyword.put_new(opts, :forward, forward)) do
        {:ok, _} -> :ok
        {:error, error} -> raise ArgumentError, "config :dolphin, links: #{Exception.message(error)}"
      end
    end

    :ok
  end

  @doc """
  Starts a link. Options as for `Dolphin.Link.Connection.start_link/1` (but
  `:endpoint`); `:forward` may be given as endpoint strings. An endpoint that
  cannot be read or opened gives a `Dolphin.Link.EndpointError`.
  """
  @spec connect(String.t(), keyword()) :: {:ok, pid()} | {:error, EndpointError.t()}
  def connect(endpoint, opts \\ []) do
    with {:ok, %Endpoint{} = ep} <- Endpoint.parse(endpoint),
         :ok <- network_name(endpoint, opts[:network]),
         {:ok, forward} <- parse_all(Keyword.get(opts, :forward, [])) do
      opts = Keyword.put(opts, :forward, forward)

      case DynamicSupervisor.start_child(Dolphin.Instance.names().links, {Dolphin.Link.Connection, [endpoint: ep] ++ opts}) do
        {:ok, pid} -> {:ok, pid}
        {:error, {:already_started, _}} -> {:error, %EndpointError{endpoint: endpoint, reason: :already_connected}}
        {:error, {{:cannot_open, where, why}, _}} -> {:error, %EndpointError{endpoint: where, reason: :cannot_open, detail: why}}
        {:error, {:cannot_open, where, why}} -> {:error, %EndpointError{endpoint: where, reason: :cannot_open, detail: why}}
        {:error, other} -> {:error, %EndpointError{endpoint: endpoint, reason: :failed, detail: inspect(other)}}
      end
    end
  end

  @doc """
  Stops a link that `connect/2` started. When it returns, the link's sockets
  are closed (its port can be opened again at once) and its telemetry log
  is written out.
  """
  @spec disconnect(pid()) :: :ok
  def disconnect(link) do
    # :not_found: it was stopped already.
    _ = DynamicSupervisor.terminate_child(Dolphin.Instance.names().links, link)
    :ok
  end

  # A network's name ends a vehicle's qualified name ("1@radio2"): some text.
  defp network_name(_endpoint, nil), do: :ok
  defp network_name(_endpoint, name) when is_binary(name) and name != "", do: :ok
  defp network_name(endpoint, other), do: {:error, %EndpointError{endpoint: endpoint, reason: :failed, detail: "network: a network's name is some text, such as \"radio2\", got: #{inspect(other)}"}}

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
