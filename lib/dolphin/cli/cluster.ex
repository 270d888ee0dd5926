defmodule Dolphin.CLI.Cluster do
  @moduledoc false
  # The cluster options that mix dolphin.run, dolphin.console and
  # dolphin.station share (--sname, --name, --cookie, --join): checked when
  # the command line is parsed, then distribution started and the stations
  # joined (Dolphin.Cluster).

  
  @switches [sname: :string, name: :string, cookie: :string, join: :keep]

  @doc false
  def switches, do: @switches

  @doc false
  # The usage problem of the cluster options, if any. `alive?`: the VM is a
  # distributed node already (`iex --sname op -S mix ...`), so --join needs
  # no --sname.
  @spec check(keyword(), boolean()) :: :ok | {:error, String.t()}
  def check(opts, alive? \\ false) do
    named? = opts[:sname] != nil or opts[:name] != nil or alive?

    cond do
      opts[:sname] && opts[:name] -> {:error, "--sname and --name do not go together"}
      opts[:sname] && String.contains?(opts[:sname], "@") -> {:error, "--sname takes a short name (no @HOST; --name NAME@HOST for a long one), got #{inspect(opts[:sname])}"}
      joins(opts) != [] and not named? -> {:error, "--join needs this node to have a name: give --sname NAME or --name NAME@HOST"}
      opts[:cookie] && not named? -> {:error, "--cookie goes with --sname or --name"}
      bad = Enum.find(joins(opts), &(not String.match?(&1, ~r/^[^@\s]+@[^@\s]+$/))) -> {:error, "--join takes a node name NAME@HOST, got #{inspect(bad)}"}
      true -> :ok
    end
  end

  @doc false
  def joins(opts), do: Keyword.get_values(opts, :join)

  @doc false
  # Starts distribution (when a name is given) and joins each --join'ed
  # node. `speedup`: the one the user asked for, or nil to adopt the first
  # station's (the stations after it must then agree with it). Returns what
  # to print, or the first error.
  @spec start(keyword(), number() | nil) :: {:ok, [String.t()]} | {:error, Dolphin.CommandLineError.t()}
  def start(opts, speedup) do
    with {:ok, lines} <- start_node(opts) do
      # After the first station, the speed-up is the cluster's: every other must agree with it.
      joins(opts)
      |> Enum.reduce_while({:ok, lines, speedup}, fn node, {:ok, lines, k} ->
        case Dolphin.Cluster.join(node, speedup: k) do
          :ok -> {:cont, {:ok, lines ++ ["joined #{node}: #{count(node)} vehicle(s)"], Dolphin.Clock.speedup()}}
          {:error, e} -> {:halt, {:error, Dolphin.CommandLineError.failed("--join #{node}", e)}}
        end
      end)
      |> case do
        {:ok, lines, _k} -> {:ok, lines}
        error -> error
      end
    end
  end

  defp count(node) do
    node = String.to_atom(node)
    Enum.count(Dolphin.Cluster.Mirror.routes(), fn {_id, r} -> node in r.stations end)
  end

  defp start_node(opts) do
    {name, type} =
      cond do
        opts[:sname] -> {opts[:sname], :shortnames}
        opts[:name] -> {opts[:name], :longnames}
        true -> {nil, nil}
      end

    cond do
      name != nil ->
        case Dolphin.Cluster.start_node(name, type, opts[:cookie]) do
          {:ok, node} -> {:ok, ["node #{node}"]}
          {:error, e} -> {:error, Dolphin.CommandLineError.failed("--#{if type == :shortnames, do: "sname", else: "name"} #{name}", e)}
        end

      opts[:cookie] ->
        Node.set_cookie(String.to_atom(opts[:cookie]))
        {:ok, []}

      true ->
        {:ok, []}
    end
  end
end
