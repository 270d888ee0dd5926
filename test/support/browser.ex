defmodule Dolphin.Test.Browser do
  @moduledoc """
  A headless Chromium for tests tagged `:browser`: the page as the browser
  built it (its DOM after the page's scripts ran) and a screenshot.

  The binary is `$CHROMIUM`, else `chromium` or `chromium-browser` on the
  PATH (Debian's `chromium`, which scripts/bootstrap installs).
  """

  @doc "The browser's path, or nil."
  @spec executable() :: String.t() | nil
  def executable do
    case System.get_env("CHROMIUM") do
      path when path in [nil, ""] -> System.find_executable("chromium") || System.find_executable("chromium-browser")
      path -> path
    end
  end

  @doc "Whether a browser is there."
  @spec available?() :: boolean()
  def available?, do: executable() != nil

  @doc """
  The DOM of `file` (or an `http://` address) once loaded, serialised;
  `profile` is a directory of the test's own; `args`, more of Chromium's
  options (`--virtual-time-budget=MS`: let the page's scripts run that long).
  """
  @spec dump_dom(Path.t(), Path.t(), [String.t()]) :: String.t()
  def dump_dom(file, profile, args \\ []), do: run(args ++ ["--dump-dom", url(file)], profile)

  @doc "A screenshot of `file` (or an `http://` address; PNG) at `width` x `height` into `png`."
  @spec screenshot(Path.t(), Path.t(), Path.t(), {pos_integer(), pos_integer()}, [String.t()]) :: :ok
  def screenshot(file, png, profile, {width, height} \\ {1400, 1000}, args \\ []) do
    run(args ++ ["--screenshot=#{png}", "--window-size=#{width},#{height}", "--hide-scrollbars", url(file)], profile)
    :ok
  end

  defp url("http://" <> _ = address), do: address
  defp url(file), do: "file://" <> Path.expand(file)

  # --no-sandbox: Chromium's sandbox refuses to start as root (CI, containers).
  # A profile directory of its own, so that tests running at once do not
  # share one. Its complaints (no D-Bus in a container...) go to a log there,
  # shown only when it fails.
  defp run(args, profile) do
    File.mkdir_p!(profile)
    log = Path.join(profile, "chromium.log")
    base = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--user-data-dir=#{profile}"]
    shell = ~s(log="$1"; shift; exec "$@" 2>>"$log")
    {out, status} = System.cmd("sh", ["-c", shell, "sh", log, executable() | base ++ args], env: [{"HOME", profile}])
    if status != 0, do: raise("#{executable()} exited with status #{status}:\n" <> File.read!(log))
    out
  end
end
