defmodule Dolphin.ScriptErrorsTest do
  # What a script's author reads when the script is wrong: their file, line
  # and words, never the module the script is compiled into.
  # Swaps :standard_error while compiling and runs scripts: not async.
  use ExUnit.Case, async: false

  import ExUnit.CaptureIO

  alias Dolphin.Script
  alias Dolphin.Script.Error
  alias Mix.Tasks.Dolphin.Run

  defp compile(source, file) do
    case Script.compile_string(source, file) do
      {:ok, script} -> Script.purge(script) && {:ok, script}
      error -> error
    end
  end

  test "an unknown word names the nearest words of the language, not the script's module" do
    assert {:error, %Error{line: 3} = e} = compile("use Dolphin.Script\nv = pick(type: :uav)\nexecute(wait_fro(battery(v) > 0.5))\n", "typo.exs")
    text = Error.format(e)
    assert text =~ "typo.exs:3: undefined function wait_fro/1"
    assert text =~ "did you mean wait_for/1"
    refute text =~ "Dolphin.Script.Compiled"
  end

  test "a fence that cannot be one is an error at its line, saying why" do
    home = "home = location(38.43462, -8.86118, 0)\n_ = home\n"

    # A zone's mistake at the zone's line, the block's at the block's.
    for {body, at, why} <- [
          {"include polygon([home, Dolphin.Geo.offset(home, 10, 0)])", 5, "a polygon needs at least 3 corners, got 2"},
          {"exclude polygon([home, Dolphin.Geo.offset(home, 100, 100), Dolphin.Geo.offset(home, 100, 0), Dolphin.Geo.offset(home, 0, 100)])", 5,
           "the polygon crosses itself: its edge 1 (corner 1 to 2) crosses its edge 3"},
          {"max_altitude 10\n  min_altitude 30", 4, "the fence's altitude band is upside down: min_altitude 30 m is above max_altitude 10 m"},
          {"on_breach :explode", 4, "on_breach is one of :rtl, :land, :hold, :report, got: :explode"},
          {"include circle(home, 0)", 5, "a circle's radius is a number of metres, more than 0, got: 0"}
        ] do
      source = "use Dolphin.Script\n" <> home <> "fence do\n  " <> body <> "\nend\n"
      {:ok, script} = Script.compile_string(source, "fence.exs")
      assert {:error, %Error{line: line, message: message}} = Script.run(script, []), body
      Script.purge(script)
      assert {line, message} == {at, "ArgumentError: " <> why}
    end

    # A word the block does not have is not a fence's: the compiler says so at its line.
    assert {:error, %Error{line: 4, message: message}} = compile("use Dolphin.Script\nfence do\n  max_altitude 100\n  max_height 10\nend\n", "word.exs")
    assert message =~ "undefined function max_height/1"
  end

  test "compiler warnings are said in the script's terms" do
    warnings = capture_io(:stderr, fn -> assert {:ok, _} = compile("use Dolphin.Script\nx = 1\nmessage(\"hi\")\n", "unused.exs") end)
    assert warnings =~ ~s(unused.exs:2: warning: variable "x" is unused)
    refute warnings =~ "Compiled"
  end

  test "a type conflict is one warning at its line, its text whole and without Elixir's trailer" do
    source = "use Dolphin.Script\nx = 1\nmessage \"\#{x.speed}\"\n"
    warnings = capture_io(:stderr, fn -> compile(source, "types.exs") end)
    assert warnings =~ ~r/\Atypes.exs:3: warning: incompatible types:\n/
    assert warnings =~ "\n      x.speed\n"
    refute warnings =~ "Conflict found at"
    refute warnings =~ "__script__"
    refute warnings =~ "Compiled"
  end

  test "an unknown word inside a block, which Elixir only warns about, is said as the error says it" do
    source = "use Dolphin.Script\nv = pick()\nm = mission \"m\" do\n  takeoff 10\n  wait_fro(1, 2)\nend\nexecute %{v => m}\n"
    warnings = capture_io(:stderr, fn -> assert {:error, %Error{line: 4}} = compile(source, "block.exs") end)
    assert warnings =~ "block.exs:5: warning: undefined function wait_fro/2: no word of the language or of Elixir has that name; did you mean wait_for/2"
    refute warnings =~ "Compiled"
    refute warnings =~ "expected"
  end

  test "a syntax error says the token, where it is and what is not closed, in plain words" do
    source = "use Dolphin.Script\n\nforever do\n  v = pick(timeout: seconds(1)\n  release(v)\nend\n"
    assert {:error, %Error{kind: :syntax, line: 6, column: 1} = e} = compile(source, "syntax.exs")
    assert Error.format(e) == ~s|syntax.exs:6:1: syntax error: unexpected reserved word "end": the "(" at line 4 is missing terminator ")"|
  end

  test "a word of the language given bad arguments while compiling names the line" do
    source = "use Dolphin.Script\n\nt = one_of do\n  1\nend\n"
    assert {:error, %Error{line: 3, message: m}} = compile(source, "one_of.exs")
    assert m =~ "one_of takes clauses"
  end

  @tag :tmp_dir
  test "a mission on a fake vehicle says that fake vehicles run only test tasks", %{tmp_dir: dir} do
    file = Path.join(dir, "fake.exs")
    File.write!(file, "use Dolphin.Script\nv = pick(timeout: seconds(1))\nexecute(on(mission \"m\" do\n  home location(40.4, -7.3, 800)\n  take_off location(40.4, -7.3, 820)\nend, v))\n")
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    assert 1 == Run.main([file, "--fake", "1"], out: out, err: err)
    {_, text} = StringIO.contents(err)
    assert text =~ ~s|mission "m" needs a MAVLink vehicle; vehicle 1 is a fake vehicle (--fake), which runs only fake-platform tasks|
    refute text =~ "not connected"
  end

  @tag :tmp_dir
  test "a port already in use fails the run (exit 1), it is not bad usage (exit 2)", %{tmp_dir: dir} do
    {:ok, taken} = :gen_udp.open(0, ip: {127, 0, 0, 1})
    {:ok, port} = :inet.port(taken)
    file = Path.join(dir, "idle.exs")
    File.write!(file, "use Dolphin.Script\nmessage(\"hi\")\n")
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    assert 1 == Run.main([file, "--connect", "udpin:127.0.0.1:#{port}", "--no-tlog"], out: out, err: err)
    {_, text} = StringIO.contents(err)
    assert text =~ "udpin:127.0.0.1:#{port}"
    assert text =~ "in use"
    refute text =~ "usage:"

    # A malformed endpoint is bad usage.
    assert 2 == Run.main([file, "--connect", "udp:127.0.0.1:1"], out: out, err: err)
    :gen_udp.close(taken)
  end
end
