defmodule Dolphin.Console.MissionSource do
  @moduledoc false
  # Missions as the Elixir source of a script's `mission "name" do ... end`
  # block (for `mix dolphin.plan import` and the console's download/1), and
  # MISSION_ITEM_INT lists downloaded from a vehicle as missions. Pure.
  #
  # The source gives the mission back exactly: evaluated with
  # Dolphin.DSL.Mission and Dolphin.DSL.Values imported, it is a mission
  # equal to the one printed (floats are printed in their shortest exact
  # form, integers stay integers).

  alias Dolphin.Geo.Location
  alias Dolphin.Mission
  alias Dolphin.Mission.Command

  @doc false
  @spec to_source(Mission.t()) :: String.t()
  def to_source(%Mission{} = mission) do
    home = if mission.home, do: ["  home " <> value(mission.home)], else: []
    body = home ++ Enum.map(mission.commands, &("  " <> command(&1)))
    Enum.join(["mission #{inspect(mission.name)} do" | body] ++ ["end"], "\n")
  end

  @doc false
  # One command as the block writes it: `take_off location(40.1, -7.2, 1200.0), 15`.
  @spec command(Command.t()) :: String.t()
  def command(%Command{kind: :item, args: args}) do
    name =
      case Dolphin.MAVLink.Ardupilotmega.enum_name(:mav_cmd, args[:command]) do
        {:ok, atom} -> inspect(atom)
        _ -> Integer.to_string(args[:command])
      end

    opts =
      [params: args[:params], frame: args[:frame], x: args[:x], y: args[:y], z: args[:z]] ++
        if(args[:autocontinue] == 0, do: [autocontinue: 0], else: [])

    "item " <> name <> ", " <> Enum.map_join(opts, ", ", fn {k, v} -> "#{k}: #{value(v)}" end)
  end

  def command(%Command{kind: kind, args: args}) do
    case for({k, v} <- args, {k, v} != {:base, :previous}, do: value(v)) do
      [] -> "#{kind}()"
      shown -> "#{kind} " <> Enum.join(shown, ", ")
    end
  end

  defp value(%Location{lat: lat, lon: lon, h: h}), do: "location(#{value(lat)}, #{value(lon)}, #{value(h)})"
  # 1200.0 rather than Erlang's shortest form, 1.2e3.
  defp value(f) when is_float(f) and f == trunc(f) and abs(f) < 1.0e15, do: "#{trunc(f)}.0"
  defp value(f) when is_float(f), do: Float.to_string(f)
  defp value(n) when is_integer(n), do: Integer.to_string(n)
  defp value(list) when is_list(list), do: "[" <> Enum.map_join(list, ", ", &value/1) <> "]"
  defp value(other), do: inspect(other)

  @doc false
  # A mission from items as a vehicle gives them back (item 0 its home):
  # through the QGroundControl plan reader, so that each item becomes the
  # command that gives it back exactly, else a raw `item`.
  @spec from_items([struct()], String.t()) :: {:ok, Mission.t()} | {:error, Dolphin.Mission.PlanError.t()}
  def from_items([home | items], name) do
    plan = %{
      "fileType" => "Plan",
      "version" => 1,
      "mission" => %{
        "version" => 2,
        "plannedHomePosition" => [home.x / 1.0e7, home.y / 1.0e7, home.z],
        "items" => Enum.map(items, &plan_item/1)
      }
    }

    Mission.from_plan(plan, name: name)
  end

  def from_items([], _name), do: {:error, %Dolphin.Mission.PlanError{reason: :not_a_plan, detail: "no items (not even home)"}}

  # The plan reader takes the plan's non-_INT frames (0, 3, 10) back to _INT (5, 6, 11).
  @global [0, 3, 5, 6, 10, 11]
  @plan_frame %{5 => 0, 6 => 3, 11 => 10}

  defp plan_item(item) do
    global? = item.frame in @global
    {x, y} = if global?, do: {item.x / 1.0e7, item.y / 1.0e7}, else: {item.x / 1, item.y / 1}

    %{
      "type" => "SimpleItem",
      "autoContinue" => item.autocontinue != 0,
      "command" => item.command,
      "doJumpId" => item.seq,
      "frame" => Map.get(@plan_frame, item.frame, item.frame),
      "params" => Enum.map([item.param1, item.param2, item.param3, item.param4, x, y, item.z], &json_number/1)
    }
  end

  defp json_number(n) when is_number(n), do: n
  defp json_number(_nan), do: :null
end
