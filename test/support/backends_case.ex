defmodule Dolphin.Test.BackendsCase do
  @moduledoc """
  A test module comparing examples on the simulator and on ArduCopter SITL:
  one test per example, each run as a user runs it on both backends and
  compared by `Dolphin.Test.ExampleRun.assert_backends_agree/2`.

      use Dolphin.Test.BackendsCase,
        cases: [{"photo_patrol", 1, nil, 15, %{"Field patrol" => 1, "Home" => 1}}]

  A case is `{example, vehicles, --for (nil: it ends by itself), SITL's
  speed-up, the least each mission name must have been flown on both}`.
  `beside: false`: the simulator's run after SITL's, not beside it
  (`Dolphin.Test.ExampleRun.assert_backends_agree/3`).
  Tagged `:sitl` (and `example: NAME`): run when a SITL binary is found.
  """

  defmacro __using__(opts) do
    quote bind_quoted: [cases: Keyword.fetch!(opts, :cases), beside: Keyword.get(opts, :beside, true)] do
      use ExUnit.Case, async: false

      @moduletag :sitl
      @moduletag :tmp_dir
      @moduletag timeout: 900_000

      @cases cases
      @beside beside

      setup do
        on_exit(&Dolphin.Test.GroundStation.forget_vehicles/0)
      end

      for {name, _, _, _, _} <- cases do
        @tag example: name
        test "#{name}.exs: the same history on ArduCopter SITL as on the simulator", %{tmp_dir: dir} do
          Dolphin.Test.ExampleRun.assert_backends_agree(dir, List.keyfind(@cases, unquote(name), 0), beside: @beside)
        end
      end
    end
  end
end
