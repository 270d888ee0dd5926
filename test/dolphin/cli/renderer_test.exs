defmodule Dolphin.CLI.RendererTest do
  use ExUnit.Case, async: true

  # The renderers here subscribe to nothing: each is sent its events by hand.

  alias Dolphin.CLI.Renderer

  defp start(opts) do
    {:ok, out} = StringIO.open("")
    {:ok, r} = Renderer.start_link([out: out, origin_ms: 1_000, subscribe: false] ++ opts)
    {r, out}
  end

  defp printed(out), do: out |> StringIO.contents() |> elem(1)

  test "prints the events a run's log shows, stamped from the origin, and all it was sent before stop/1 returns" do
    {r, out} = start([])
    send(r, {:dolphin, :events, %{event: :armed, vehicle: 1, at_ms: 2_500}})
    send(r, {:dolphin, :events, %{event: :allocated, run: 1, allocation: %{3 => 1}, at_ms: 2_600}})
    send(r, {:dolphin, :events, %{event: :message, text: "hello", at_ms: 3_000}})
    :ok = Renderer.stop(r)

    assert printed(out) == "[    1.5 s] vehicle 1 armed\n[    2.0 s] message: hello\n"
  end

  test "quiet: the script's messages only; notes always" do
    {r, out} = start(quiet: true)
    send(r, {:dolphin, :events, %{event: :armed, vehicle: 1, at_ms: 2_500}})
    send(r, {:dolphin, :events, %{event: :message, text: "hello", at_ms: 3_000}})
    Renderer.note(r, "interrupted")
    :ok = Renderer.stop(r)

    assert [message, note] = printed(out) |> String.split("\n", trim: true)
    assert message == "[    2.0 s] message: hello"
    assert note =~ ~r/^\[ *-?\d+\.\d s\] interrupted$/
  end

  test "an OTP process: :sys.get_state/1 shows which task each vehicle flies" do
    {r, _out} = start([])
    send(r, {:dolphin, :events, %{event: :task_started, task_id: 4, parent_id: nil, kind: :test, name: "survey", vehicle: 2, at_ms: 1_000}})
    assert %{tasks: %{2 => {4, "survey"}}, live: false} = :sys.get_state(r)
    :ok = Renderer.stop(r)
  end

  test "terminal/1: a device that is not standard output is never a terminal" do
    {:ok, out} = StringIO.open("")
    assert Renderer.terminal(out) == nil
  end
end
