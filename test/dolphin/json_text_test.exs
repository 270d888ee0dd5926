defmodule Dolphin.JSONTextTest do
  use ExUnit.Case, async: true

  alias Dolphin.JSONText

  doctest JSONText

  test "where the JSON goes wrong, by line and column, and what is there" do
    assert JSONText.decode(~s|{\n  "a": 1\n  "b": 2\n}|) == {:error, ~s|line 3, column 3 (byte 14): unexpected "\\"b\\": 2"|}
    assert JSONText.decode(~s|[1, 2]\nx|) == {:error, ~s|line 2, column 1 (byte 8): more after the end of the JSON value: "x"|}
    assert JSONText.decode(~s|{"é": 0x}|) == {:error, ~s|line 1, column 8 (byte 9): unexpected "x}"|}
    assert {:error, "line 1, column 9 (byte 9): a bad string" <> _} = JSONText.decode(~s|{"a": "\\q"}|)
    assert JSONText.decode("  \n ") == {:error, "the file is empty: no JSON value in it"}
    assert JSONText.decode("[1, 2") == {:error, "line 1, column 6 (byte 6): the text ends before the JSON value does"}
  end
end
