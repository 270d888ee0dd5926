defmodule Dolphin.Web do
  @moduledoc """
  A live view of a run in the browser: the flight report's page
  (`Dolphin.Report`: map, time line, plots, summary) served over HTTP while
  the run goes on, and kept up to date in the page: vehicles move on the
  map (a dot where each one is, its track behind it), task bars grow on
  their lanes, and a table says what each vehicle is doing now.

      {:ok, web} = Dolphin.Web.start(port: 8080)
      Dolphin.Web.url(web)   #=> "http://127.0.0.1:8080/"
      Dolphin.Web.stop(web)

  From the shell, `mix dolphin.run SCRIPT --web 8080`; from the console,
  `web(8080)`.

  ## What it serves

    * `GET /` — the page as it is now (it reads well without its script);
      a fleet of more than 50 vehicles is shown a page of 50 at a time,
      `/?page=N` (in the order of their names), each page counting the whole
      fleet in one line (connected, lost, armed, flying a task, the emptiest
      batteries) and drawing its own vehicles and the events that concern
      them; a page number that is not one is a 400;
      `/?frames=N`: the page stops following after N frames (a snapshot
      through the live path, for a headless browser, whose `--dump-dom`
      would wait for ever on an open stream);
    * `GET /events` (`/events?page=N`: page N's) — a stream of Server-Sent Events: a `frame` event (one
      line of JSON, `{"pieces": [[id, html], ...]}`) with the parts of the
      page that changed (each section, the legend, the line under the
      heading), at most four times a second (less when the page takes long
      to draw), the whole state first; an `end` event when the view stops;
      a comment line every 15 s;
    * anything else is 404, any method but GET is 405: the page sends no
      commands, it only watches.

  ## How it keeps up

  One process per view (`start/1`) owns the listening socket and a bounded
  model of the run, fed by the vehicles' views (`Dolphin.Vehicles.subscribe/1`,
  and the `:vehicles` topic for the ones discovered later) and by the events
  (`Dolphin.Events`): at most 4,000 positions per vehicle (past that,
  every other one is dropped: the track keeps its shape), 2,000 samples of
  battery, modes and arming, and the last 5,000 events. Each client has a
  process of its own that writes to its socket; the view casts to it and
  never waits. A client that falls behind (frames piling up in its
  mailbox) is sent nothing until it has caught up and then everything that
  changed meanwhile; one that stops reading is closed after 5 s of blocked
  writes. So no browser can slow the fleet.

  ## Where it listens

  On 127.0.0.1 unless `bind:` says otherwise (`"0.0.0.0"` to be seen from
  other machines: it shows where the vehicles are to anyone who asks). A
  port in use, or an address that is not this machine's, is
  `{:error, %Dolphin.Web.Error{}}`.
  """

  alias Dolphin.Web.{Error, Hub}

  @doc """
  Starts a live view. Options:

    * `:port` (required) — the TCP port; 0 picks a free one (see `port/1`);
    * `:bind` — the address to listen on, default `"127.0.0.1"`;
    * `:title` — the page's heading, default "Live run";
    * `:tlog` — the run's telemetry log, named on the page;
    * `:origin_ms` — the `Dolphin.Clock` time the run started (the page's
      time zero), default now;
    * `:owner` — a process: the view stops when it ends;
    * `:history` — events that came before (`Dolphin.Events` maps, oldest
      first), shown as if seen live;
    * `:name` — a name to register the view under.

  It runs under the application's `Dolphin.Web.Supervisor`, not linked to
  the caller: stop it with `stop/1` (or give `:owner`). Its browsers'
  processes run under `Dolphin.Web.Connections`.
  """
  @spec start(keyword()) :: {:ok, pid()} | {:error, Error.t()}
  def start(opts) when is_list(opts) do
    case Keyword.fetch(opts, :port) do
      {:ok, port} when is_integer(port) and port in 0..65_535 -> :ok
      {:ok, other} -> raise ArgumentError, "Dolphin.Web.start/1: :port must be a TCP port (0..65535), got: #{inspect(other)}"
      :error -> raise ArgumentError, "Dolphin.Web.start/1: the :port option is required"
    end

    unless is_binary(Keyword.get(opts, :bind, "")), do: raise(ArgumentError, "Dolphin.Web.start/1: :bind must be an address as text, got: #{inspect(opts[:bind])}")

    case Hub.start(opts) do
      {:ok, pid} -> {:ok, pid}
      {:error, {:shutdown, %Error{} = e}} -> {:error, e}
    end
  end

  @doc "Stops a live view: its clients' streams end (their pages say so) and its port is free again."
  @spec stop(pid()) :: :ok
  def stop(web) do
    GenServer.stop(web, :normal, 15_000)
  catch
    # Already stopped (its owner ended first).
    :exit, _ -> :ok
  end

  @doc "The TCP port a live view listens on."
  @spec port(pid()) :: :inet.port_number()
  def port(web), do: GenServer.call(web, :port)

  @doc "The address of a live view's page."
  @spec url(pid()) :: String.t()
  def url(web) do
    {bind, port} = GenServer.call(web, :where)
    # Listening on every address: this machine's own is one of them.
    host = %{"0.0.0.0" => "127.0.0.1", "::" => "::1"}[bind] || bind
    host = if String.contains?(host, ":"), do: "[#{host}]", else: host
    "http://#{host}:#{port}/"
  end
end
