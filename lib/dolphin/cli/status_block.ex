defmodule Dolphin.CLI.StatusBlock do
  @moduledoc """
  The live status block of `mix dolphin.run` on a terminal: one line per
  vehicle — mode, armed, battery bar, mission progress, the link's round trip
  and loss each way once measured (and which link, once a vehicle heard on
  several has changed the one it is reached through), and the task it flies
  — redrawn in place under the scrolling log of events.

      iex> v = %Dolphin.Vehicles.View{id: 2, mode: :auto, armed?: true, battery: 0.72, mission_progress: {3, 42}, relative_altitude: 380.4}
      iex> Dolphin.CLI.StatusBlock.vehicle_line(v, "Survey Area 1")
      "  2  AUTO      armed     [#######---]  72 %  alt  380 m  item  3/42  Survey Area 1"
      iex> v = %{v | link: %{rtt_ms: 45, loss_in: 0.1, loss_out: 0.12}}
      iex> Dolphin.CLI.StatusBlock.vehicle_line(v, nil)
      "  2  AUTO      armed     [#######---]  72 %  alt  380 m  item  3/42  link 45 ms, loss in 10 % / out 12 %"
      iex> Dolphin.CLI.StatusBlock.vehicle_line(v, nil, "udpin:0.0.0.0:14551")
      "  2  AUTO      armed     [#######---]  72 %  alt  380 m  item  3/42  link 45 ms, loss in 10 % / out 12 % via udpin:0.0.0.0:14551"

  `render/5` draws the block (a header and the lines) and `redraw/2` gives the
  ANSI sequence that replaces a block of `n` lines with a new one.

  A fleet larger than the block's room (`max_lines`, from the terminal's
  height) is summed up: a line of counts (armed, on a task, lost, the
  batteries' range), then the vehicles that most need a look — lost ones,
  then the emptiest batteries — and how many are not shown.
  """

  alias Dolphin.Vehicles.View, as: Vehicle

  @bar 10

  @doc """
  The block's lines for these vehicles; `tasks` maps a vehicle id to the name
  of the task it flies; `clock_ms` is the run's clock time; `paths` maps a
  vehicle id to the name of the link it is reached through, for vehicles
  heard on several (`path_changed` events).
  """
  @spec render([Vehicle.t()], %{optional(Dolphin.Vehicles.Id.t()) => String.t()}, non_neg_integer(), %{optional(Dolphin.Vehicles.Id.t()) => String.t()}, pos_integer() | :infinity) ::
          [String.t()]
  def render(vehicles, tasks, clock_ms, paths \\ %{}, max_lines \\ :infinity) do
    header = "── #{clock(clock_ms)} ── #{length(vehicles)} vehicle(s) " <> String.duplicate("─", 40)
    line = &vehicle_line(&1, Map.get(tasks, &1.id), Map.get(paths, &1.id))

    if max_lines == :infinity or length(vehicles) < max_lines do
      [header | Enum.map(Enum.sort_by(vehicles, & &1.id), line)]
    else
      # Room for the header, the counts, and the line that says how many are left out.
      shown = vehicles |> Enum.sort_by(&concern/1) |> Enum.take(max(max_lines - 3, 1))
      left = length(vehicles) - length(shown)
      [header, counts(vehicles, tasks) | Enum.map(Enum.sort_by(shown, & &1.id), line)] ++ ["  ... and #{left} more (mix dolphin.console lists them all: vehicles())"]
    end
  end

  @doc """
  The counts line of a large fleet's block.

      iex> fleet = [%Dolphin.Vehicles.View{id: 1, armed?: true, battery: 0.9}, %Dolphin.Vehicles.View{id: 2, battery: 0.4}, %Dolphin.Vehicles.View{id: 3, connected?: false}]
      iex> Dolphin.CLI.StatusBlock.counts(fleet, %{1 => "Hop"})
      "  1 armed, 1 on a task, 1 lost; battery 40..90 %"
  """
  @spec counts([Vehicle.t()], map()) :: String.t()
  def counts(vehicles, tasks) do
    armed = Enum.count(vehicles, &(&1.connected? and &1.armed?))
    lost = Enum.count(vehicles, &(not &1.connected?))
    on_task = Enum.count(vehicles, &Map.has_key?(tasks, &1.id))

    batteries =
      case for(%{battery: b} when is_number(b) <- vehicles, do: round(b * 100)) do
        [] -> ""
        known -> "; battery #{Enum.min(known)}..#{Enum.max(known)} %"
      end

    "  #{armed} armed, #{on_task} on a task, #{lost} lost" <> batteries
  end

  # Lost vehicles first, then the emptiest batteries, then by id.
  defp concern(%Vehicle{connected?: false, id: id}), do: {0, 0, id}
  defp concern(%Vehicle{battery: b, id: id}) when is_number(b), do: {1, b, id}
  defp concern(%Vehicle{id: id}), do: {2, 0, id}

  @doc "One vehicle's line; `via`, the link it is reached through when it is heard on several (else nil)."
  @spec vehicle_line(Vehicle.t(), String.t() | nil, String.t() | nil) :: String.t()
  def vehicle_line(%Vehicle{} = v, task, via \\ nil) do
    mode = v.mode |> mode_name() |> String.pad_trailing(9)
    state = if(not v.connected?, do: "LOST", else: if(v.armed?, do: "armed", else: "disarmed")) |> String.pad_trailing(9)

    item =
      case v.mission_progress do
        nil -> "item  ?/?"
        {_reached, 0} -> "no mission"
        {reached, total} -> "item #{String.pad_leading(Integer.to_string(reached), 2)}/#{total}"
      end

    alt = if v.relative_altitude, do: "alt #{String.pad_leading(Integer.to_string(round(v.relative_altitude)), 4)} m", else: "alt    ? m"

    line = "#{String.pad_leading(Dolphin.Fleet.VehicleSet.format(v.id), 3)}  #{mode} #{state} #{battery(v.battery)}  #{alt}  #{String.pad_trailing(item, 10)}"

    line =
      case Dolphin.Console.Format.link_figures(v.link || %{}) do
        [] -> line
        figures -> line <> "  link " <> Enum.join(figures, ", ")
      end

    line = if via, do: line <> if(String.contains?(line, "  link "), do: " via ", else: "  link via ") <> via, else: line

    if task, do: line <> "  " <> task, else: String.trim_trailing(line)
  end

  @doc "The ANSI text that erases the last `previous` lines and writes `lines` in their place."
  @spec redraw(non_neg_integer(), [String.t()]) :: iodata()
  def redraw(previous, lines) do
    up = if previous > 0, do: "\e[#{previous}A", else: ""
    [up, "\r\e[J", Enum.map(lines, &[&1, ?\n])]
  end

  @doc "The ANSI text that erases the last `n` lines (before the log goes on)."
  @spec erase(non_neg_integer()) :: iodata()
  def erase(0), do: []
  def erase(n), do: ["\e[#{n}A", "\r\e[J"]

  defp battery(nil), do: "[" <> String.duplicate("?", @bar) <> "]    ?  "

  defp battery(fraction) do
    full = fraction |> Kernel.*(@bar) |> round() |> max(0) |> min(@bar)
    percent = fraction |> Kernel.*(100) |> round() |> Integer.to_string() |> String.pad_leading(3)
    "[" <> String.duplicate("#", full) <> String.duplicate("-", @bar - full) <> "] #{percent} %"
  end

  defp mode_name(nil), do: "?"
  defp mode_name({:custom, n}), do: "mode #{n}"
  defp mode_name(mode), do: mode |> Atom.to_string() |> String.upcase()

  defp clock(ms) do
    s = div(ms, 1000)
    "#{div(s, 3600)}:#{pad(rem(div(s, 60), 60))}:#{pad(rem(s, 60))}"
  end

  defp pad(n), do: n |> Integer.to_string() |> String.pad_leading(2, "0")
end
