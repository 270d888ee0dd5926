defmodule Dolphin.MAVLink.JSONTest do
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.JSON

  doctest Dolphin.MAVLink.JSON
  doctest Dolphin.MAVLink.JSONError

  test "numbers: exact integers, subnormals, -0.0, exponents" do
    assert JSON.decode("[0, -0, 1e2, 1E-2, 2.5e+3, -5e-324, 4.9e-324, 1.7976931348623157e308, -9223372036854775808]") ==
             {:ok, [0, 0, 100.0, 0.01, 2500.0, -5.0e-324, 5.0e-324, 1.7976931348623157e308, -9_223_372_036_854_775_808]}

    {:ok, [z]} = JSON.decode("[-0.0]")
    assert <<z::float-64>> == <<-0.0::float-64>>
  end

  test "strings: escapes, surrogate pairs, bytes as \\u00XX" do
    assert JSON.decode(~S(["a\"b\\c\/\n\t", "\u00e9", "\ud83d\ude00", "\u0001"])) == {:ok, ["a\"b\\c/\n\t", <<0xE9>>, "😀", <<1>>]}
  end

  test "objects and literals" do
    assert JSON.decode(~s( {"a": {"b": [true, false, null]}, "c": {}} )) == {:ok, %{"a" => %{"b" => [true, false, nil]}, "c" => %{}}}
  end

  test "errors say what and where" do
    assert error("[1, 2") == "expected , or ] in an array at byte 5, found end of input"
    assert "expected a value at byte 1" <> _ = error("[}")
    assert "unexpected data after the value" <> _ = error("{} x")
    assert "number out of range" <> _ = error("1e999")
    assert "lone surrogate" <> _ = error(~S("\ud800"))
    # Exactly four hex digits: no sign.
    assert "bad \\u escape" <> _ = error(~S("\u-004"))
    assert "bad \\u escape" <> _ = error(~S("\u+041"))
  end

  test "writing keeps order, -0.0, specials, and escapes bytes" do
    out = JSON.encode({:object, [{"z", -0.0}, {"a", [:nan, :infinity, :neg_infinity, {:nan, 1}]}, {"s", <<"q\"", 0, 255>>}]})
    assert IO.iodata_to_binary(out) == ~S({"z":-0.0,"a":["NaN","Infinity","-Infinity","NaN"],"s":"q\"\u0000\u00ff"})
    assert {:ok, %{"s" => <<"q\"", 0, 255>>}} = JSON.decode(IO.iodata_to_binary(out))
  end

  defp error(text) do
    assert {:error, %Dolphin.MAVLink.JSONError{} = e} = JSON.decode(text)
    Exception.message(e)
  end
end
