defmodule Dolphin.Link.Endpoint do
  @moduledoc """
  Where the ground station meets its vehicles, written as in MAVProxy and
  ArduPilot SITL:

    * `udpin:ADDR:PORT` — listen on a UDP port; vehicles send to us and each is
      answered at its own source address (what SITL's `udpclient` and most
      radios do). The default, `udpin:0.0.0.0:14550`.
    * `udpout:HOST:PORT` — send to a fixed address first (a vehicle or a router
      that listens).
    * `tcp:HOST:PORT` — connect to a TCP server (SITL listens on 5760).

      iex> Dolphin.Link.Endpoint.parse("udpin:0.0.0.0:14550")
      {:ok, %Dolphin.Link.Endpoint{kind: :udpin, host: "0.0.0.0", address: {0, 0, 0, 0}, port: 14550}}
      iex> {:error, error} = Dolphin.Link.Endpoint.parse("udp:1.2.3.4:5")
      iex> Exception.message(error)
      ~s|endpoint "udp:1.2.3.4:5": unknown kind "udp" (expected udpin, udpout or tcp)|
  """

  alias Dolphin.Link.EndpointError

  @enforce_keys [:kind, :host, :address, :port]
  defstruct [:kind, :host, :address, :port]

  @type kind :: :udpin | :udpout | :tcp
  @type t :: %__MODULE__{kind: kind(), host: String.t(), address: :inet.ip_address(), port: :inet.port_number()}

  @kinds %{"udpin" => :udpin, "udpout" => :udpout, "tcp" => :tcp}

  @doc "Parses an endpoint string; host names are resolved (IPv4 or IPv6)."
  @spec parse(String.t()) :: {:ok, t()} | {:error, EndpointError.t()}
  def parse(string) when is_binary(string) do
    with {:ok, kind, host, port} <- split(string),
         {:ok, address} <- resolve(host) do
      {:ok, %__MODULE__{kind: kind, host: host, address: address, port: port}}
    else
      {:error, reason, detail} -> {:error, %EndpointError{endpoint: string, reason: reason, detail: detail}}
    end
  end

  @doc "Like `parse/1`, raising `ArgumentError` with the error's message."
  @spec parse!(String.t()) :: t()
  def parse!(string) do
    case parse(string) do
      {:ok, endpoint} -> endpoint
      {:error, error} -> raise ArgumentError, Exception.message(error)
    end
  end

  @doc "The endpoint as a string again."
  @spec to_string(t()) :: String.t()
  def to_string(%__MODULE__{kind: kind, host: host, port: port}), do: "#{kind}:#{host}:#{port}"

  defp split(string) do
    # The port is after the last colon, so IPv6 hosts may keep theirs ("udpin:[::1]:14550").
    with [kind, rest] <- String.split(string, ":", parts: 2),
         {:ok, kind} <- kind(kind),
         [host, port] <- split_last(rest) do
      case Integer.parse(port) do
        {port, ""} when port in 0..65_535 -> {:ok, kind, String.trim(host, "[") |> String.trim("]"), port}
        _ -> {:error, :bad_port, port}
      end
    else
      {:error, _, _} = error -> error
      _ -> {:error, :bad_form, nil}
    end
  end

  defp kind(kind) do
    case Map.fetch(@kinds, kind) do
      {:ok, k} -> {:ok, k}
      :error -> {:error, :unknown_kind, kind}
    end
  end

  defp split_last(rest) do
    case :binary.matches(rest, ":") do
      [] -> :error
      matches -> {pos, 1} = List.last(matches); [binary_part(rest, 0, pos), binary_part(rest, pos + 1, byte_size(rest) - pos - 1)]
    end
  end

  defp resolve(""), do: {:error, :no_host, nil}

  defp resolve(host) do
    chars = String.to_charlist(host)

    case :inet.parse_address(chars) do
      {:ok, address} ->
        {:ok, address}

      {:error, _} ->
        case :inet.getaddr(chars, :inet) do
          {:ok, address} -> {:ok, address}
          {:error, _} -> {:error, :unresolved, host}
        end
    end
  end
end
