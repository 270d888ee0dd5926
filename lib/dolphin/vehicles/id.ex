defmodule Dolphin.Vehicles.Id do
  @moduledoc """
  A vehicle is where it is heard plus its MAVLink system id.

  Most vehicles leave the factory as system id 1, so a fleet may hold
  several vehicles with one system id, each on its own *network*: a link
  (`--connect`), or on a `udpin` link one remote address. The first vehicle
  heard with a system id is named by the id alone (`1`), as every script
  and example names its vehicles; another with the same system id, on
  another network, is named by a *qualified name*, `"SYSID@NETWORK"`: the
  system id and the network it was first heard on, e.g.
  `"1@127.0.0.1:14561"` (a `udpin` link's remote address) or
  `"1@udpout:127.0.0.1:14570"` (a link, by its name), or a network a link
  was given a name for (its `:network` option: every address it hears is
  that network), e.g. `"1@sim2"`, the simulator's second network of
  `--sim` beyond 254 vehicles. Every vehicle also
  answers to its qualified name, the first one included
  (`Dolphin.Vehicles.resolve/1`), so a script that must not depend on which
  vehicle was heard first names both by network.

  On a cluster's controller (`Dolphin.Cluster`), a vehicle is named as its
  ground station names it; when another station hears another autopilot
  behind an id a vehicle there already has, that station's is `"ID@NODE"`,
  its id there and that station's node name (`"30@gs2"`, `"1@sim2@gs2"`;
  `Dolphin.Cluster.Mirror`). There a vehicle answers to that name only,
  not to the qualified name its station also knows it by: networks are
  each station's own.

  A vehicle id is therefore a system id (an integer) or a qualified name (a
  string): `Dolphin.Vehicles`, the fleet's `pick(id: ...)`, events, the
  console and the reports carry it as it is.

      iex> Dolphin.Vehicles.Id.sysid(3)
      3
      iex> Dolphin.Vehicles.Id.sysid("1@127.0.0.1:14561")
      1
      iex> Dolphin.Vehicles.Id.qualified(1, {"udpin:127.0.0.1:14550", {{127, 0, 0, 1}, 14561}})
      "1@127.0.0.1:14561"
      iex> Dolphin.Vehicles.Id.qualified(1, {"radio2", nil})
      "1@radio2"
      iex> Dolphin.Vehicles.Id.parse("1@radio2")
      {:ok, "1@radio2"}
      iex> Dolphin.Vehicles.Id.parse("1")
      {:ok, 1}
      iex> Dolphin.Vehicles.Id.parse("300@radio2")
      :error
      iex> Dolphin.Vehicles.Id.parse("01@radio2")
      :error
  """

  @typedoc "A system id (the first vehicle heard with it) or a qualified name, `\"SYSID@NETWORK\"`."
  @type t :: non_neg_integer() | String.t()

  @doc """
  Whether `term` has the shape of a vehicle id (a guard): a non-negative
  integer or a string. `valid?/1` checks a name's spelling too.
  """
  defguard is_id(term) when (is_integer(term) and term >= 0) or is_binary(term)

  @doc "The MAVLink system id of vehicle `id`."
  @spec sysid(t()) :: non_neg_integer()
  def sysid(id) when is_integer(id), do: id

  def sysid(id) when is_binary(id) do
    {:ok, sysid, _network} = split(id)
    sysid
  end

  @doc """
  The qualified name of the vehicle with system id `sysid` heard first on
  path `via` (`t:Dolphin.Vehicles.Paths.via/0`): its network is the remote
  address on a `udpin` link, else the link's name.
  """
  @spec qualified(0..255, term()) :: String.t()
  def qualified(sysid, via), do: "#{sysid}@#{network(via)}"

  @doc """
  The network of path `via`: the network its link was given
  (`Dolphin.Link.Connection`'s `:network`), else a `udpin` link's remote
  address, else the link's name.
  """
  @spec network(term()) :: String.t()
  def network({link, _address} = via), do: Dolphin.Link.Connection.network(link) || by_address(via)

  def network(link), do: by_address({link, nil})

  @doc """
  The qualified name of the vehicle with system id `sysid` heard first on
  path `via` by the path's address even on a named network: for a second
  vehicle with the same system id on one named network (a misconfigured
  fleet), which that network's name alone cannot tell apart.
  """
  @spec qualified_by_address(0..255, term()) :: String.t()
  def qualified_by_address(sysid, via), do: "#{sysid}@#{by_address(via)}"

  defp by_address({_link, {ip, port}}) when is_tuple(ip) and is_integer(port), do: "#{:inet.ntoa(ip)}:#{port}"
  defp by_address({link, nil}), do: name(link)

  defp name(link) when is_binary(link), do: link
  defp name(link), do: link |> inspect() |> String.replace(~r/\s+/, "")

  @doc """
  Vehicle ids in the order a listing shows them: system ids first, then
  the qualified names network by network, each by its system id (`"2@sim2"`
  before `"10@sim2"`).

      iex> Dolphin.Vehicles.Id.sort(["10@sim2", 7, "2@sim2", "1@sim10", 3])
      [3, 7, "2@sim2", "10@sim2", "1@sim10"]
  """
  @spec sort([t()]) :: [t()]
  def sort(ids), do: Enum.sort_by(ids, &order/1)

  defp order(id) when is_integer(id), do: {0, [], id}

  defp order(id) when is_binary(id) do
    case split(id) do
      {:ok, sysid, network} -> {1, natural(network), sysid}
      _ -> {2, id, 0}
    end
  end

  # A network's name with its runs of digits as numbers ("sim2" before "sim10").
  defp natural(name), do: for(part <- Regex.split(~r/\d+/, name, include_captures: true, trim: true), do: if(part =~ ~r/\A\d+\z/, do: {0, String.to_integer(part)}, else: {1, part}))

  @doc """
  A vehicle id from what a user wrote: a system id (an integer, or digits)
  or a qualified name `"SYSID@NETWORK"`; `:error` for anything else.
  """
  @spec parse(term()) :: {:ok, t()} | :error
  def parse(id) when is_integer(id) and id >= 0, do: {:ok, id}

  def parse(text) when is_binary(text) do
    case Integer.parse(text) do
      {id, ""} when id >= 0 -> {:ok, id}
      _ -> with {:ok, _sysid, _network} <- split(text), do: {:ok, text}
    end
  end

  def parse(_other), do: :error

  @doc "Whether `id` is a vehicle id: a system id or a well-formed qualified name."
  @spec valid?(term()) :: boolean()
  def valid?(id), do: parse(id) == {:ok, id}

  defp split(text) do
    with [digits, network] when network != "" <- String.split(text, "@", parts: 2),
         {sysid, ""} when sysid in 0..255 <- Integer.parse(digits),
         # One spelling per vehicle: "1@x", never "01@x".
         true <- Integer.to_string(sysid) == digits do
      {:ok, sysid, network}
    else
      _ -> :error
    end
  end
end
