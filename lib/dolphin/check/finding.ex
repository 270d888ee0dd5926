defmodule Dolphin.Check.Finding do
  @moduledoc """
  One finding of the pre-flight check (`Dolphin.Check`): its `severity`
  (`:error` — the script should not fly as it is; `:warning` — it may fly,
  but look; `:note` — what the check could not decide), its `kind` (an atom
  naming the rule: `:compile`, `:position`, `:below_ground`, `:too_far`,
  `:too_high`, `:empty_mission`, `:no_take_off`, `:take_off_height`,
  `:take_off_pitch`, `:loiter_radius`, `:speed`, `:jump`, `:no_camera`,
  `:pick`, `:allocation`, `:script`, `:energy`, `:low_reserve`, `:endless`,
  `:busy_loop`, `:waiting`, `:ask`, `:mission` — a mission whose items
  cannot be made at all), where (`file`, `line`, nil when unknown) and a
  `message` that says what is wrong.

      iex> f = %Dolphin.Check.Finding{severity: :error, kind: :too_far, file: "s.exs", line: 4, message: "mission \\"M\\": item 2 is 2400 m from home (limit 1000 m)"}
      iex> Dolphin.Check.Finding.format(f)
      ~S|s.exs:4: error: mission "M": item 2 is 2400 m from home (limit 1000 m)|
  """

  defstruct [:severity, :kind, :file, :line, :message]

  @type severity :: :error | :warning | :note
  @type t :: %__MODULE__{severity: severity(), kind: atom(), file: String.t() | nil, line: pos_integer() | nil, message: String.t()}

  @doc "`file:line: severity: message` (as much of the place as is known)."
  @spec format(t()) :: String.t()
  def format(%__MODULE__{} = f) do
    where = Enum.reject([f.file && Path.relative_to_cwd(f.file), f.line], &is_nil/1) |> Enum.join(":")
    if where == "", do: "#{f.severity}: #{f.message}", else: "#{where}: #{f.severity}: #{f.message}"
  end

  @doc "A finding as a map for JSON (binary keys)."
  @spec to_map(t()) :: map()
  def to_map(%__MODULE__{} = f) do
    %{"severity" => Atom.to_string(f.severity), "kind" => Atom.to_string(f.kind), "file" => f.file, "line" => f.line, "message" => f.message}
  end
end
