defmodule Dolphin.Web.Error do
  @moduledoc """
  A live view (`Dolphin.Web`) that could not be served: `reason` is
  `:address_in_use`, `:bad_address` (the bind address does not parse),
  `:address_not_available` (no interface has it) or another `:inet` error;
  `address` and `port` are what was asked for.

      iex> Exception.message(%Dolphin.Web.Error{reason: :address_in_use, address: "127.0.0.1", port: 8080})
      "cannot serve the live view on 127.0.0.1:8080: the port is in use"
      iex> Exception.message(%Dolphin.Web.Error{reason: :bad_address, address: "localhost:1", port: 8080})
      ~s(cannot serve the live view on localhost:1:8080: "localhost:1" is not an IP address)
  """

  defexception [:reason, :address, :port]

  @type t :: %__MODULE__{reason: atom(), address: String.t(), port: :inet.port_number()}

  @impl true
  def message(%__MODULE__{} = e), do: "cannot serve the live view on #{e.address}:#{e.port}: " <> why(e)

  defp why(%{reason: :address_in_use}), do: "the port is in use"
  defp why(%{reason: :bad_address, address: a}), do: "#{inspect(a)} is not an IP address"
  defp why(%{reason: :address_not_available}), do: "no network interface of this machine has that address"
  defp why(%{reason: :permission_denied}), do: "permission denied (ports below 1024 need privileges)"
  defp why(%{reason: r}), do: r |> :inet.format_error() |> to_string()
end
