defmodule Dolphin.Link.EndpointTest do
  use ExUnit.Case, async: true

  alias Dolphin.Link.{Endpoint, EndpointError}

  doctest Endpoint
  doctest EndpointError

  test "the three kinds, names resolved, IPv6 in brackets" do
    assert {:ok, %Endpoint{kind: :udpout, address: {127, 0, 0, 1}, port: 14_551}} = Endpoint.parse("udpout:localhost:14551")
    assert {:ok, %Endpoint{kind: :tcp, address: {127, 0, 0, 1}, port: 5760}} = Endpoint.parse("tcp:127.0.0.1:5760")
    assert {:ok, %Endpoint{kind: :udpin, address: {0, 0, 0, 0, 0, 0, 0, 1}, port: 14_550}} = Endpoint.parse("udpin:[::1]:14550")
    assert Endpoint.to_string(Endpoint.parse!("udpin:0.0.0.0:14550")) == "udpin:0.0.0.0:14550"
  end

  test "errors say what is wrong" do
    assert error("udpin:0.0.0.0") == "endpoint \"udpin:0.0.0.0\": expected KIND:HOST:PORT, e.g. udpin:0.0.0.0:14550"
    assert error("udpin:0.0.0.0:70000") == "endpoint \"udpin:0.0.0.0:70000\": bad port \"70000\" (expected 0..65535)"
    assert error("udpout::5") == "endpoint \"udpout::5\": no host"
    assert error("udpout:no-such-host.invalid:5") == "endpoint \"udpout:no-such-host.invalid:5\": cannot resolve host \"no-such-host.invalid\""
    assert_raise ArgumentError, ~r/unknown kind/, fn -> Endpoint.parse!("serial:/dev/ttyUSB0:57600") end
  end

  test "errors name the rule broken" do
    assert {:error, %EndpointError{reason: :bad_form, endpoint: "udpin:0.0.0.0"}} = Endpoint.parse("udpin:0.0.0.0")
    assert {:error, %EndpointError{reason: :unknown_kind, detail: "serial"}} = Endpoint.parse("serial:/dev/ttyUSB0:57600")
    assert {:error, %EndpointError{reason: :no_host}} = Endpoint.parse("udpout::5")
  end

  defp error(string) do
    assert {:error, %EndpointError{} = e} = Endpoint.parse(string)
    Exception.message(e)
  end
end
