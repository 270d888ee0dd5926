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

  `render/3` draws the block (a header and the lines) and `redraw/2` gives the
  ANSI sequence that replaces a block of `n` lines with a new one.
  """

  alias Dolphin.Vehicles.View, as: Vehicle

  @bar 10

  @doc """
  The block's lines for these vehicles; `tasks` maps a vehicle id to the name
  of the task it flies; `clock_ms` is the run's clock time; `paths` maps a
  vehicle id to the name of the link it is reached through, for vehicles
  heard on several (`path_changed` events).
  """
  @spec render([Vehicle.t()], %{optional(non_neg_integer()) => String.t()}, non_neg_integer(), %{optional(non_neg_integer()) => String.t()}) ::
          [String.t()]
  def render(vehicles, tasks, clock_ms, paths \\ %{}) do
    header = "── #{clock(clock_ms)} ── #{length(vehicles)} vehicle(s) " <> String.duplicate("─", 40)
    [header | Enum.map(Enum.sort_by(vehicles, & &1.id), &vehicle_line(&1, Map.get(tasks, &1.id), Map.get(paths, &1.id)))]
  end

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
