defmodule Dolphin.Cluster.CLITest do
  # The cluster's command lines (mix dolphin.station, dolphin.run --join)
  # and bad input when joining, with :peer stations (Dolphin.Test.Cluster).
  # Distribution and the clock are global: not async.
  use ExUnit.Case, async: false

  @moduletag :cluster
  @moduletag :capture_log
  @moduletag timeout: 120_000

  alias Dolphin.Test.{Cluster, Wait}
  alias Mix.Tasks.Dolphin.{Run, Station}

  @speedup 50

  setup do: Cluster.setup_controller(@speedup)

  defp io do
    {:ok, out} = StringIO.open("")
    {:ok, err} = StringIO.open("")
    {out, err}
  end

  defp text(device), do: device |> StringIO.contents() |> elem(1)

  test "mix dolphin.station serves its vehicles, prints them, and stops when told" do
    {out, err} = io()
    me = self()
    task = Task.async(fn -> Station.main(~w(--sname gsx --sim 1 --first-sysid 40 --speedup 50), out: out, err: err, ready: me) end)
    assert_receive {Station, :ready, _node}, 20_000
    assert text(out) =~ "ground station"
    assert text(out) =~ "1 simulated vehicle(s) [40]"
    Wait.until(fn -> text(out) =~ "vehicle 40 discovered" end, 10_000, fn -> text(out) end)
    send(task.pid, {Station, :stop})
    assert Task.await(task, 20_000) == 0
    assert text(err) == ""
  end

  test "usage errors exit with 2 and say what is wrong" do
    {out, err} = io()
    assert Station.main(~w(--sim 1), out: out, err: err) == 2
    assert text(err) =~ "a station needs a node name: give --sname NAME or --name NAME@HOST"

    {out, err} = io()
    assert Station.main(~w(--sname gsx --sim 1 --tlog /no/such/dir/gs.tlog), out: out, err: err) == 2
    assert text(err) =~ "mix dolphin.station: --tlog /no/such/dir/gs.tlog: cannot create it: no such directory /no/such/dir"

    script = Path.expand("../../../examples/single_vehicle.exs", __DIR__)
    {out, err} = io()
    assert Run.main([script, "--join", "gs1@127.0.0.1"], out: out, err: err) == 2
    assert text(err) =~ "--join needs this node to have a name: give --sname NAME or --name NAME@HOST"

    {out, err} = io()
    assert Run.main([script, "--sname", "ctl", "--join", "gs1"], out: out, err: err) == 2
    assert text(err) =~ ~s(--join takes a node name NAME@HOST, got "gs1")

    {out, err} = io()
    assert Run.main([script, "--sname", "a", "--name", "b@h"], out: out, err: err) == 2
    assert text(err) =~ "--sname and --name do not go together"
  end

  test "mix dolphin.console takes --join on a node that has a name (iex --sname), and checks it" do
    # This VM is the distributed node ctl<N>@127.0.0.1, as under `iex --sname`.
    assert {:ok, opts} = Mix.Tasks.Dolphin.Console.parse(~w(--join gs1@127.0.0.1 --join gs2@127.0.0.1))
    assert Keyword.get_values(opts, :join) == ["gs1@127.0.0.1", "gs2@127.0.0.1"]
    assert {:error, e} = Mix.Tasks.Dolphin.Console.parse(~w(--join gs1))
    assert Exception.message(e) =~ ~s(--join takes a node name NAME@HOST, got "gs1")
  end

  test "joining an unreachable node: exit 1, cannot reach it" do
    script = Path.expand("../../../examples/single_vehicle.exs", __DIR__)
    {out, err} = io()
    assert Run.main([script, "--sname", "ctl", "--join", "nobody@127.0.0.1", "--no-tlog", "--quiet"], out: out, err: err) == 1
    assert text(err) =~ "--join nobody@127.0.0.1: cannot reach nobody@127.0.0.1: no node named nobody is registered with EPMD on 127.0.0.1"
  end

  test "a wrong cookie: the connection is refused, and the cookie is named as the likely cause" do
    gs = Cluster.start_node("gsc", cookie: :not_the_same)
    assert {:error, %Dolphin.Cluster.Error{reason: :refused} = e} = Dolphin.Cluster.join(gs.node)
    assert Exception.message(e) =~ "cannot reach #{gs.node}: the connection was refused (the cookies may differ; a node cannot tell for sure)"
  end

  test "a node at another speed-up is refused, naming both; without one of its own it adopts the station's" do
    gs = Cluster.start_station("gs1", speedup: 40)
    assert {:error, %Dolphin.Cluster.Error{reason: :speedup} = e} = Dolphin.Cluster.join(gs.node, speedup: 50)
    assert Exception.message(e) =~ "#{gs.node} runs at speed-up 40, this node was asked for 50"
    assert :ok = Dolphin.Cluster.join(gs.node)
    assert Dolphin.Clock.speedup() == 40
  end

  @tag :tmp_dir
  test "mix dolphin.run --join flies a station's vehicle and records its events", %{tmp_dir: dir} do
    gs = Cluster.start_station("gs1", sysids: [7])
    # The station hears its vehicle before the run joins it (the line below counts it).
    Wait.until(fn -> 7 in Cluster.call(gs.peer, Dolphin.Vehicles, :list, []) end, 1_500, fn -> "vehicle 7 on the station" end)
    script = Path.join(dir, "hop.exs")

    File.write!(script, """
    use Dolphin.Script
    v = pick(id: 7, timeout: seconds(60))
    execute wait_for(position(v) != nil)
    h = position(v)
    hop =
      mission "Hop" do
        home h
        take_off %{h | h: h.h + 10}
        return_home_and_land()
      end
    execute on(hop, v)
    """)

    events = Path.join(dir, "events.jsonl")
    {out, err} = io()
    code = Run.main([script, "--sname", "ctl", "--join", Atom.to_string(gs.node), "--events", events, "--no-tlog"], out: out, err: err, plain: true)
    assert code == 0, text(out) <> text(err)
    assert text(out) =~ "joined #{gs.node}: 1 vehicle(s)"
    lines = File.read!(events)
    assert lines =~ ~s("event":"station_joined")
    assert lines =~ ~s("event":"armed","vehicle":7)
    assert lines =~ ~s("event":"script_finished","reason":null,"result":"done")
  end
end
