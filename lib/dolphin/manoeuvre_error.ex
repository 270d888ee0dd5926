defmodule Dolphin.ManoeuvreError do
  @moduledoc """
  A manoeuvre of `Dolphin.Vehicles.Manoeuvres` that did not succeed: which
  manoeuvre (`:hold`, `:arm`, or `:command` for one command: GUIDED, the
  take-off, the landing...), on which vehicle, the exchange the vehicle
  refused (`action`, in words), the refusal itself (`refusal`: a
  `Dolphin.CommandError`, or for a hold the `Dolphin.ManoeuvreError` of its
  last resort), `waited_ms` (arming: how long the autopilot refused before
  the manoeuvre gave up; `nil` when a refusal was final at once) and
  `texts`, the STATUSTEXTs the autopilot sent during the manoeuvre (newest
  first), which often say why.

      iex> refusal = %Dolphin.CommandError{command: :mav_cmd_do_set_mode, vehicle: 2, result: :denied, attempts: 1}
      iex> e = %Dolphin.ManoeuvreError{manoeuvre: :command, vehicle: 2, action: "GUIDED", refusal: refusal, texts: [{3, "Mode change failed"}]}
      iex> Exception.message(e)
      "GUIDED refused: vehicle 2 refused MAV_CMD_DO_SET_MODE: MAV_RESULT_DENIED: the autopilot says \\"Mode change failed\\""
      iex> Exception.message(%Dolphin.ManoeuvreError{manoeuvre: :arm, vehicle: 2, action: "arming", refusal: refusal, waited_ms: 120_000, texts: [{6, "x"}, {3, "PreArm: Need Position Estimate"}]})
      "arming refused for 120 s: the autopilot says \\"PreArm: Need Position Estimate\\""
  """

  defexception [:manoeuvre, :vehicle, :action, :refusal, :waited_ms, texts: []]

  @type t :: %__MODULE__{
          manoeuvre: :hold | :arm | :command,
          vehicle: byte(),
          action: String.t(),
          refusal: Dolphin.CommandError.t() | t(),
          waited_ms: non_neg_integer() | nil,
          texts: [{integer(), String.t()}]
        }

  @impl true
  def message(%__MODULE__{manoeuvre: :hold, refusal: refusal}),
    do: "the vehicle could not be made to hold position: #{Exception.message(refusal)}"

  # Arming that the autopilot kept refusing: its pre-arm check says why.
  def message(%__MODULE__{action: "arming", waited_ms: ms} = e) when is_integer(ms),
    do: "arming refused for #{div(ms, 1000)} s#{says(e.texts, ["Arm", "PreArm"])}"

  def message(%__MODULE__{action: "arming", refusal: refusal}), do: "arming: #{Exception.message(refusal)}"

  def message(%__MODULE__{} = e), do: "#{e.action} refused: #{Exception.message(e.refusal)}#{says(e.texts, [])}"

  @doc """
  The autopilot's latest explanation among `texts` (newest first) as
  `": the autopilot says \\"...\\""`, or `""`: a text with one of `prefixes`
  (`"PreArm"` matches `"PreArm: ..."`), or with no prefixes given, one of
  severity WARNING or worse.

      iex> Dolphin.ManoeuvreError.says([{6, "Arming motors"}, {4, "EKF variance"}], [])
      ": the autopilot says \\"EKF variance\\""
      iex> Dolphin.ManoeuvreError.says([{6, "Arming motors"}], [])
      ""
  """
  @spec says([{integer(), String.t()}], [String.t()]) :: String.t()
  def says(texts, prefixes) do
    found =
      Enum.find(texts, fn {severity, text} ->
        Enum.any?(prefixes, &String.starts_with?(text, &1 <> ":")) or (prefixes == [] and severity <= 4)
      end)

    case found do
      {_, text} -> ": the autopilot says \"#{text}\""
      nil -> ""
    end
  end
end
