defmodule Dolphin.Test.Hops do
  @moduledoc """
  A script in which each of several vehicles, picked by id, flies a hop of
  its own from where it stands: up, north, and home to land. Tests that fly
  vehicles from several places (stations, networks) compare what each flew.
  """

  @doc """
  The compiled script for `hops`, one `{vehicle id, climb, north}` each: the
  vehicle takes off `climb` metres above where it stands, flies `north`
  metres north and comes home to land; all at once (`execute`). Vehicle i's
  mission is named "Hop i".
  """
  def script(hops) do
    picks =
      for {{id, climb, north}, i} <- Enum.with_index(hops, 1) do
        """
        v#{i} = pick(id: #{inspect(id)}, timeout: seconds(60))
        execute wait_for(position(v#{i}) != nil)
        h#{i} = position(v#{i})
        hop#{i} =
          mission "Hop #{i}" do
            home h#{i}
            take_off %{h#{i} | h: h#{i}.h + #{climb}}
            move #{north}, 0, 0
            return_home_and_land()
          end
        """
      end

    tasks = Enum.map_join(1..length(hops), ", ", &"v#{&1} => hop#{&1}")
    {:ok, script} = Dolphin.Script.compile_string("use Dolphin.Script\n" <> Enum.join(picks) <> "execute %{#{tasks}}\n", "hops.exs")
    script
  end
end
