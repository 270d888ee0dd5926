defprotocol Dolphin.Engine.Taskable do
  @moduledoc """
  What can be used as a task: every combinator applies `to_task/1` to its
  arguments, so a value of another module — a `%Dolphin.Mission{}`, a test
  platform task — can be composed directly (`until(survey, battery(v) < 0.3)`).

  The engine's own task structs implement it as the identity. A platform
  implements it for its task values by returning a platform task:

      defimpl Dolphin.Engine.Taskable, for: Dolphin.Mission do
        def to_task(mission), do: Dolphin.Engine.platform_task(Dolphin.Mission.Platform, mission)
      end

  See `Dolphin.Engine.Platform` for the behaviour such a platform implements.
  """

  @doc "The engine task this value stands for."
  @spec to_task(t()) :: Dolphin.Engine.Task.t()
  def to_task(value)
end
