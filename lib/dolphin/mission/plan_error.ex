defmodule Dolphin.Mission.PlanError do
  @moduledoc """
  A QGroundControl plan that could not be read: `reason` names what is
  wrong (`:invalid_json`, `:not_a_plan`, `:unsupported_version`,
  `:unsupported_item`, `:invalid_item`, `:invalid_home`, `:invalid_fence`),
  `detail` says where.

      iex> Exception.message(%Dolphin.Mission.PlanError{reason: :not_a_plan, detail: ~s(fileType is "Mission")})
      ~s(not a QGroundControl plan: fileType is "Mission")
  """

  defexception [:reason, :detail]

  @type t :: %__MODULE__{reason: atom(), detail: String.t() | nil}

  @impl true
  def message(%__MODULE__{reason: reason, detail: detail}) do
    base =
      case reason do
        :invalid_json -> "the plan is not valid JSON"
        :not_a_plan -> "not a QGroundControl plan"
        :unsupported_version -> "unsupported plan version"
        :unsupported_item -> "unsupported plan item"
        :invalid_item -> "invalid plan item"
        :invalid_home -> "invalid planned home position"
        :invalid_fence -> "invalid geofence or rally points"
        other -> "invalid plan (#{other})"
      end

    if detail, do: base <> ": " <> detail, else: base
  end
end
