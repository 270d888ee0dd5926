defmodule Dolphin.Link.EndpointTest do
  use ExUnit.Case, async: true

  alias Dolphin.Link.Endpoint

  doctest Endpoint

  test "the three kinds, names resolved, IPv6 in brackets" do
    assert {:ok, %Endpoint{kind: :udpout, address: {127, 0, 0, 1}, port: 14_551}} = Endpoint.parse("udpout:localhost:14551")
    assert {:ok, %Endpoint{kind: :tcp, address: {127, 0, 0, 1}, port: 5760}} = Endpoint.parse("tcp:127.0.0.1:5760")
    assert {:ok, %Endpoint{kind: :udpin, address: {0, 0, 0, 0, 0, 0, 0, 1}, port: 14_550}} = Endpoint.parse("udpin:[::1]:14550")
    assert Endpoint.to_string(Endpoint.parse!("udpin:0.0.0.0:14550")) == "udpin:0.0.0.0:14550"
  end

  test "errors say what is wrong" do
    assert {:error, "endpoint \"udpin:0.0.0.0\": expected KIND:HOST:PORT, e.g. udpin:0.0.0.0:14550"} = Endpoint.parse("udpin:0.0.0.0")
    assert {:error, "endpoint \"udpin:0.0.0.0:70000\": bad port \"70000\" (expected 0..65535)"} = Endpoint.parse("udpin:0.0.0.0:70000")
    assert {:error, "endpoint \"udpout::5\": no host"} = Endpoint.parse("udpout::5")
    assert {:error, "endpoint \"udpout:no-such-host.invalid:5\": cannot resolve host \"no-such-host.invalid\""} = Endpoint.parse("udpout:no-such-host.invalid:5")
    assert_raise ArgumentError, ~r/unknown kind/, fn -> Endpoint.parse!("serial:/dev/ttyUSB0:57600") end
  end
end
