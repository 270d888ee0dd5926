defmodule Mix.Tasks.Dolphin.RunLogsTest do
  # The telemetry log every run keeps. Runs simulated vehicles, changes the
  # working directory and the clock's speed-up: not async.
  use ExUnit.Case, async: false

  alias Mix.Tasks.Dolphin.Run

  @moduletag :tmp_dir
  @moduletag timeout: 120_000

  @script """
  use Dolphin.Script
  v = pick(type: :uav, timeout: seconds(30))
  execute(wait_for(position(v) != nil))
  pause(seconds(5))
  release(v)
  """

  setup do
    on_exit(&Dolphin.Test.GroundStation.forget_vehicles/0)
  end

  defp main(argv) do
    {:ok, io} = StringIO.open("")
    code = Run.main(argv, out: io, err: io)
    {code, elem(StringIO.contents(io), 1)}
  end

  test "a run writes a dated .tlog under logs/ that pymavlink reads; --no-tlog writes none", %{tmp_dir: dir} do
    File.write!(Path.join(dir, "hover.exs"), @script)

    File.cd!(dir, fn ->
      {0, output} = main(["hover.exs", "--sim", "1", "--speedup", "50"])
      assert [tlog] = Path.wildcard("logs/*-hover.tlog")
      assert tlog =~ ~r"^logs/\d{4}-\d{2}-\d{2}_\d{2}-\d{2}-\d{2}-hover\.tlog$"
      assert output =~ "telemetry log: #{tlog}"

      messages = Dolphin.Test.Pymavlink.read_tlog(Path.join(dir, tlog))
      # The vehicle's and ours, in both directions.
      assert Enum.any?(messages, &match?({1, "HEARTBEAT", _, _}, &1))
      assert Enum.any?(messages, &match?({1, "GLOBAL_POSITION_INT", _, _}, &1))
      assert Enum.any?(messages, &match?({255, "HEARTBEAT", _, _}, &1))
      timestamps = Enum.map(messages, &elem(&1, 2))
      assert timestamps == Enum.sort(timestamps)

      Dolphin.Test.GroundStation.forget_vehicles()
      File.rm_rf!("logs")
      {0, _} = main(["hover.exs", "--sim", "1", "--speedup", "50", "--no-tlog"])
      assert Path.wildcard("logs/*.tlog") == []
    end)
  end
end
