defmodule Dolphin.CLI.Renderer do
  @moduledoc """
  The process that prints a run as it goes: each event `Dolphin.EventText.logged?/2`
  keeps, as `Dolphin.EventText.event_line/2` words it, and notes of the run itself
  (`note/2`). On a terminal the log scrolls above the status block
  (`Dolphin.CLI.StatusBlock`), redrawn twice a second; elsewhere (a pipe, a
  file, CI) it is plain timestamped lines.

      {:ok, r} = Dolphin.CLI.Renderer.start_link(out: :stdio, origin_ms: Dolphin.Clock.now_ms(), terminal: Dolphin.CLI.Renderer.terminal(:stdio))
      Dolphin.CLI.Renderer.note(r, "interrupted")
      :ok = Dolphin.CLI.Renderer.stop(r)

  It subscribes to `Dolphin.Events` before `start_link/1` returns, so that
  no event of the run is missed, and prints all it was sent before `stop/1`
  returns.
  """

  use GenServer

  alias Dolphin.EventText
  alias Dolphin.CLI.StatusBlock

  # How often the status block is redrawn on a terminal (real time).
  @redraw_ms 500

  # Time `stop/1` leaves the renderer to print what it holds before it is killed.
  @stop_ms 2_000

  @doc """
  Starts a renderer linked to the caller. Options: `:out` (the device, default
  `:stdio`), `:origin_ms` (the clock time shown as zero, default now),
  `:quiet` (only the script's messages) and `:terminal` (the device path of
  the terminal `out` is, from `terminal/1`, for the status block; nil: plain
  lines); `subscribe: false` leaves the events to be sent by hand (tests).
  """
  @spec start_link(keyword()) :: GenServer.on_start()
  def start_link(opts), do: GenServer.start_link(__MODULE__, opts)

  @doc "Prints `text` in the log, stamped with the clock's time now."
  @spec note(GenServer.server(), String.t()) :: :ok
  def note(renderer, text), do: GenServer.cast(renderer, {:note, Dolphin.Clock.now_ms(), text})

  @doc "Prints what the renderer was sent and stops it (killed if it takes more than two seconds)."
  @spec stop(pid()) :: :ok
  def stop(renderer) do
    # The caller goes on after a renderer killed for taking too long.
    Process.unlink(renderer)
    GenServer.stop(renderer, :normal, @stop_ms)
  catch
    # GenServer.stop/3 gives up on it but leaves it running: a renderer stuck
    # on its output device must not outlive the run.
    :exit, :timeout ->
      Process.exit(renderer, :kill)
      :ok

    :exit, _gone ->
      :ok
  end

  @doc """
  The terminal `device` is, if it is one (a device under /dev/pts or /dev/tty
  that is not "dumb"), or nil. (`mix` runs without a shell, where OTP 25
  cannot ask the terminal itself: what the standard output is connected to tells.)
  """
  @spec terminal(IO.device()) :: String.t() | nil
  def terminal(:stdio) do
    case File.read_link("/proc/self/fd/1") do
      {:ok, "/dev/" <> kind = device} ->
        if (String.starts_with?(kind, "pts/") or String.starts_with?(kind, "tty")) and System.get_env("TERM") not in [nil, "", "dumb"], do: device

      _ ->
        nil
    end
  end

  def terminal(_device), do: nil

  # --- the process ---

  @impl true
  def init(opts) do
    if Keyword.get(opts, :subscribe, true), do: Dolphin.Events.subscribe()
    tty = Keyword.get(opts, :terminal)
    live = tty != nil
    if live, do: Process.send_after(self(), :redraw, @redraw_ms)
    {rows, columns} = if live, do: size(tty), else: {24, 80}

    {:ok,
     %{
       out: Keyword.get(opts, :out, :stdio),
       origin: Keyword.get_lazy(opts, :origin_ms, &Dolphin.Clock.now_ms/0),
       quiet: Keyword.get(opts, :quiet, false),
       live: live,
       # Lines of the status block on the screen now.
       block: 0,
       # vehicle => {task_id, name} of the platform task it flies.
       tasks: %{},
       # The link each vehicle is reached through, once it changed (path_changed).
       paths: %{},
       # The block as last rendered, drawn again under each log line.
       lines: [],
       columns: columns,
       # The block keeps the upper half of the terminal for the log.
       block_lines: max(div(rows, 2), 5)
     }}
  end

  @impl true
  def handle_info(:redraw, p) do
    Process.send_after(self(), :redraw, @redraw_ms)
    {:noreply, draw_block(p)}
  end

  def handle_info({:dolphin, :events, event}, p), do: {:noreply, print(track(p, event), event)}

  @impl true
  def handle_cast({:note, at_ms, text}, p), do: {:noreply, print_line(p, at_ms, text)}

  # Events sent before the stop but still on their way are printed too.
  @impl true
  def terminate(_reason, p), do: drain(p)

  defp drain(p) do
    receive do
      {:dolphin, :events, event} -> drain(print(track(p, event), event))
    after
      0 -> p
    end
  end

  defp print(p, event) do
    if EventText.logged?(event, p.quiet), do: print_line(p, event.at_ms, EventText.event_text(event)), else: p
  end

  defp print_line(p, at_ms, text) do
    log = EventText.stamp(at_ms, p.origin, text) <> "\n"
    # The block is erased, the line written where it was, and the block drawn
    # again below — as it was last rendered: a burst of lines from a large
    # fleet does not render it once a line.
    if p.live, do: IO.write(p.out, [StatusBlock.erase(p.block), log, StatusBlock.redraw(0, p.lines)]) && p, else: IO.write(p.out, log) && p
  end

  # Which task each vehicle flies, for the status block.
  defp track(p, %{event: :task_started, vehicle: v, task_id: id, name: name}) when v != nil, do: put_in(p.tasks[v], {id, name})

  defp track(p, %{event: :task_finished, vehicle: v, task_id: id}) when v != nil do
    case p.tasks do
      %{^v => {^id, _}} -> %{p | tasks: Map.delete(p.tasks, v)}
      _ -> p
    end
  end

  defp track(p, %{event: :path_changed, vehicle: v, to: to}), do: put_in(p.paths[v], to)
  defp track(p, _event), do: p

  defp draw_block(p, before \\ []) do
    # A fleet busy or restarting leaves the block empty for a moment, not the run broken.
    vehicles =
      try do
        for %{vehicle: v} <- Dolphin.Fleet.vehicles(), do: v
      catch
        :exit, _ -> []
      end

    tasks = Map.new(p.tasks, fn {v, {_id, name}} -> {v, name} end)
    # A line wider than the terminal would wrap, and the block's redraw would miss its rows.
    lines = StatusBlock.render(vehicles, tasks, Dolphin.Clock.now_ms() - p.origin, p.paths, p.block_lines) |> Enum.map(&String.slice(&1, 0, p.columns - 1))
    IO.write(p.out, [before, StatusBlock.redraw(p.block, lines)])
    %{p | block: length(lines), lines: lines}
  end

  # Its height and width: `mix` has no shell to ask, and the BEAM's child processes no
  # controlling terminal, so the device itself is asked.
  defp size(device) do
    with [rows, cols] <- :os.cmd(String.to_charlist("stty size < #{device} 2>/dev/null")) |> to_string() |> String.split(),
         {rows, ""} when rows > 0 <- Integer.parse(rows),
         {cols, ""} when cols > 20 <- Integer.parse(cols) do
      {rows, cols}
    else
      _ -> {24, 80}
    end
  end
end
