defmodule Dolphin.Web.ConsoleTest do
  # The console's live view is one per node, on 127.0.0.1: not async.
  use ExUnit.Case, async: false

  import ExUnit.CaptureIO

  setup do
    {:ok, _} = Application.ensure_all_started(:inets)
    on_exit(fn -> capture_io(fn -> Dolphin.Console.web(:stop) end) end)
  end

  test "web/1 serves the live view until web(:stop)" do
    said = capture_io(fn -> Dolphin.Console.web(0) end)
    assert [_, url] = Regex.run(~r{live view: (http://127\.0\.0\.1:\d+/) \(web\(:stop\) stops it\)}, said)
    assert {:ok, {{_, 200, _}, _, body}} = :httpc.request(:get, {String.to_charlist(url), []}, [timeout: 10_000], body_format: :binary)
    assert body =~ ~s(<section id="live-status">)

    assert capture_io(fn -> Dolphin.Console.web(0) end) =~ "a live view is already served at #{url}"
    assert capture_io(fn -> Dolphin.Console.web(:stop) end) =~ "live view stopped"
    assert capture_io(fn -> Dolphin.Console.web(:stop) end) =~ "no live view to stop"
  end

  test "web/1 says what is wrong, and serves nothing" do
    assert capture_io(fn -> Dolphin.Console.web("8080") end) =~ ~s|web: give a TCP port (0..65535; 0 picks a free one) or :stop, got "8080"|
    assert capture_io(fn -> Dolphin.Console.web(0, bind: {0, 0, 0, 0}) end) =~ "bind: takes an address as text"
    assert capture_io(fn -> Dolphin.Console.web(0, bind: "nowhere") end) =~ ~s(web: cannot serve the live view on nowhere:0: "nowhere" is not an IP address)
    assert capture_io(fn -> Dolphin.Console.web(0, port: 1) end) =~ "web: "
    assert Process.whereis(Dolphin.Console.Web) == nil
  end
end
