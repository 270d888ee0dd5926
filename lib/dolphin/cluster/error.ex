defmodule Dolphin.Cluster.Error do
  @moduledoc """
  Why a node could not start distribution or join a ground station:
  `reason` is `:distribution`, `:not_distributed`, `:unreachable`,
  `:refused` (the node exists but refused the connection: probably another
  cookie), `:speedup`, `:no_station` or `:not_cluster_instance` (joined from
  a process working in an instance other than the default, `Dolphin.Instance`); `detail` says it in words.

      iex> Exception.message(%Dolphin.Cluster.Error{reason: :unreachable, node: :"gs1@h", detail: "cannot reach gs1@h: EPMD on h does not answer"})
      "cannot reach gs1@h: EPMD on h does not answer"
  """

  defexception [:reason, :node, :detail]

  @type t :: %__MODULE__{reason: atom(), node: node() | String.t() | nil, detail: String.t()}

  @impl true
  def message(%__MODULE__{detail: detail}), do: detail
end
