defmodule Dolphin.Check.LoopsTest do
  use ExUnit.Case, async: true

  alias Dolphin.Check.Loops

  defp busy(source), do: Loops.busy("use Dolphin.Script\nv = pick()\n" <> source, "s.exs")

  test "a forever whose body cannot wait is busy, at the line of the loop" do
    assert busy("forever do\n  _x = 1 + 1\nend\n") == [3]
    assert busy("forever do\n  if poll(:go), do: message(\"go \#{battery(v)}\"), else: post(:idle, true)\nend\n") == [3]
    assert busy("forever(0, fn n -> n + 1 end)\n") == [3]
    assert busy("forever do\n  p = position(v)\n  _ = p && p.lat > 40 && Enum.map([1, 2], &(&1 * 2))\nend\n") == [3]
    assert busy("forever do\n  _t = wait_for(battery(v) < 0.3) >>> idle(seconds(5))\nend\n") == [3]
    assert busy("forever do\n  _m = mission \"M\" do\n    home location(40, -7, 800)\n  end\nend\n") == [3]
  end

  test "a loop with anything that may wait is not" do
    for body <- [
          "execute %{v => idle(seconds(1))}",
          "pause(seconds(1))",
          "w = pick(timeout: seconds(5))\n  release(w)",
          "_ = pick",
          "ask(\"again?\")",
          "receive do\n    :go -> :ok\n  end",
          "Process.sleep(1000)",
          "f = fn -> :ok end\n  f.()",
          "Dolphin.Script.pause(1000)",
          "Enum.each([1], fn _ -> execute(idle(seconds(1))) end)",
          "if battery(v) < 0.3, do: execute(idle(seconds(1)))"
        ] do
      assert busy("forever do\n  #{body}\nend\n") == [], body
    end
  end

  test "a loop inside a busy loop is judged by itself; a source that does not parse has none" do
    assert busy("forever do\n  forever do\n    pause(10)\n  end\nend\n") == []
    assert busy("forever do\n  forever do\n    :spin\n  end\nend\n") == [4]
    assert Loops.busy("forever do", "s.exs") == []
  end
end
