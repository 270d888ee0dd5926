defmodule Dolphin.CLI.TeardownTest do
  use ExUnit.Case, async: true

  alias Dolphin.CLI.Teardown

  # The messages received so far, in order.
  defp received(acc \\ []) do
    receive do
      m -> received([m | acc])
    after
      0 -> Enum.reverse(acc)
    end
  end

  test "a kind is undone alone, newest first; the rest after, newest first; nothing twice" do
    me = self()
    Teardown.begin()
    for {name, kind} <- [link: :vehicles, renderer: :output, sim: :vehicles, writer: :output], do: Teardown.defer(fn -> send(me, name) end, kind)

    Teardown.run(:output)
    assert received() == [:writer, :renderer]
    Teardown.run_all()
    assert received() == [:sim, :link]
    Teardown.run_all()
    assert received() == []
  end
end
