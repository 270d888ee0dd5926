defmodule Dolphin.Console.MissionFileError do
  @moduledoc """
  The missions of a file that could not be found (`mix dolphin.plan export`
  and `list`): `reason` is `:unreadable`, `:syntax` (at `line`),
  `:not_a_script` (neither a Dolphin script nor a file of `mission` blocks),
  `:crashed` or `:timeout` (evaluating its definitions) for the file at
  `path`; `:no_mission` or `:ambiguous` when the mission called `name` is
  not there or several different ones answer to it. `detail` says more (for
  `:ambiguous`, the labels of the missions that answer).

      iex> Exception.message(%Dolphin.Console.MissionFileError{reason: :no_mission, name: "Nope", detail: "the file defines no mission"})
      ~s(no mission "Nope"; the file defines no mission)
  """

  defexception [:reason, :path, :line, :name, :detail]

  @type reason :: :unreadable | :syntax | :not_a_script | :crashed | :timeout | :no_mission | :ambiguous
  @type t :: %__MODULE__{
          reason: reason(),
          path: Path.t() | nil,
          line: pos_integer() | nil,
          name: String.t() | nil,
          detail: String.t() | [String.t()] | nil
        }

  @impl true
  def message(%__MODULE__{} = e) do
    case e.reason do
      :unreadable -> "#{e.path}: cannot read: #{e.detail}"
      :syntax -> "#{e.path}:#{e.line}: syntax error: #{e.detail}"
      :not_a_script -> "#{e.path} is neither a Dolphin script (it has no `use Dolphin.Script`) nor a file of `mission` blocks"
      :crashed -> "#{e.path}: the evaluation crashed: #{e.detail}"
      :timeout -> "#{e.path}: evaluating its statements took longer than #{e.detail} (stopped)"
      :no_mission -> "no mission #{inspect(e.name)}; #{e.detail}"
      :ambiguous -> "#{length(e.detail)} different missions answer to #{inspect(e.name)} (#{Enum.join(e.detail, ", ")}): give the variable's name"
    end
  end
end
